"""Live capture: a webcam, stream or file in, whole-body SMPL-X out frame by frame (causal), watched on a local
web page and streamed as JSON lines over UDP.

    report = live(LiveConfig("0", serve=8080, udp=("127.0.0.1", 9000)))
"""

from jaxmocap.live.causal import CausalSolver, LiveSettings
from jaxmocap.live.entry import live
from jaxmocap.live.session import LiveConfig, LiveReport
from jaxmocap.live.stream import params_from_message

__all__ = ["CausalSolver", "LiveConfig", "LiveReport", "LiveSettings", "live", "params_from_message"]
