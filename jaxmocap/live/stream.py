"""Per-frame results out as JSON lines over UDP (docs/formats.md, "Live stream"): one datagram per frame, sent
without waiting (a datagram the network cannot take at once is dropped and counted, never queued)."""

import json
import socket

import numpy as np

import smplx_jax

POSE_KEYS = ("global_orient", "body_pose", "left_hand_pose", "right_hand_pose", "jaw_pose", "betas", "transl")


def person_message(person_id: int, params: smplx_jax.SMPLXParams, camera_scale, camera_trans,
                   keypoints_2d: np.ndarray, world=None) -> dict:
    """One person's entry of a frame message: the SMPL-X parameters (motion.npz's keys and layout, hand poses
    absolute), the weak-perspective camera and the 67 keypoints fitted; with ``world`` (their
    `jaxmocap.live.world.WorldKeys`), ``world_global_orient``, ``world_transl`` and ``contact``."""
    out = {"id": int(person_id)}
    out |= {key: np.round(np.asarray(getattr(params, key), np.float64), 5).tolist() for key in POSE_KEYS}
    out |= {} if world is None else {"world_global_orient": np.round(world.world_global_orient, 5).tolist(),
                                     "world_transl": np.round(world.world_transl, 5).tolist(),
                                     "contact": np.asarray(world.contact, bool).tolist()}
    return out | {"camera_scale": round(float(camera_scale), 4),
                  "camera_trans": np.round(np.asarray(camera_trans, np.float64), 3).tolist(),
                  "keypoints_2d": np.round(np.asarray(keypoints_2d, np.float64), 2).tolist()}


def frame_message(frame: int, seconds: float, people: list[dict], hands: list[dict] | None = None,
                  floor: np.ndarray | None = None, camera_from_world: np.ndarray | None = None) -> bytes:
    """A frame's JSON line: the source frame number, its time (seconds since the start), the people, with
    ``--mode hands`` the hands, and once the world frame is found its ``floor`` and ``camera_from_world``."""
    message = {"frame": int(frame), "time": round(seconds, 4), "people": people}
    message |= {} if hands is None else {"hands": hands}
    if floor is not None:
        message |= {"floor": np.round(np.asarray(floor, np.float64), 5).tolist(),
                    "camera_from_world": np.round(np.asarray(camera_from_world, np.float64), 5).tolist()}
    return (json.dumps(message, separators=(",", ":")) + "\n").encode()


def params_from_message(person: dict, num_expression: int = 10) -> smplx_jax.SMPLXParams:
    """The `smplx_jax.SMPLXParams` of one person of a frame message (eyes at rest, no expression)."""
    f = {key: np.asarray(person[key], np.float32) for key in POSE_KEYS}
    zeros = np.zeros(3, np.float32)
    return smplx_jax.SMPLXParams(f["global_orient"], f["body_pose"], f["left_hand_pose"], f["right_hand_pose"],
                                 f["jaw_pose"], zeros, zeros, f["betas"], np.zeros(num_expression, np.float32),
                                 f["transl"])


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (or ``:PORT`` for this machine) as ``(host, port)``, or `ValueError`."""
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"expected HOST:PORT, got {text!r}")
    return host or "127.0.0.1", int(port)


class UdpSender:
    """Sends each message as one datagram to ``address`` (a name is resolved once, here: `OSError` if it cannot
    be); ``sent`` and ``dropped`` count them."""

    def __init__(self, address: tuple[str, int]):
        try:
            family, _, _, _, self.address = socket.getaddrinfo(*address, type=socket.SOCK_DGRAM)[0]
        except socket.gaierror as err:
            raise OSError(f"--udp: cannot resolve {address[0]} ({err.strerror})") from None
        self.socket = socket.socket(family, socket.SOCK_DGRAM)
        self.socket.setblocking(False)
        self.sent = self.dropped = 0

    def send(self, message: bytes) -> None:
        try:
            self.socket.sendto(message, self.address)
            self.sent += 1
        except OSError:  # full buffer, no listener, network down: this datagram is lost
            self.dropped += 1

    def close(self) -> None:
        self.socket.close()
