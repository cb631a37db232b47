"""The live view: a local web page with the newest overlay frame (an MJPEG stream) and the current rates.

It serves three paths only, ``/`` (the page), ``/stream.mjpg`` and ``/stats.json``; anything else is a 404, and
no path reaches the file system. Each viewer has its own thread: `publish` only swaps the newest frame in, so a
slow viewer misses frames and a vanished one times out; capture never waits for either. `wanted` says whether a
viewer is waiting for a frame newer than the last one published: the session draws only then, so a page served
but not watched costs nothing, and a watched one is drawn no faster than its viewers ask for frames.

Who may watch: a request's ``Host`` must name the address the page listens on (on a loopback address: 127.0.0.1,
localhost or [::1], with its port), so that a web page elsewhere cannot rebind its own name to this machine and
read the camera through the user's browser; others get 403 and no body. Listening on any other address puts the
camera on the network: then every request also carries the page's token (`url`, printed at start; 403 without
it), and on a wildcard address (0.0.0.0, ::), whose names cannot be known, the token alone admits. At most
``max_viewers`` streams at once (503 beyond)."""

import hmac
import ipaddress
import json
import secrets
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import parse_qs

PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>jaxmocap live</title>
<style>body{margin:0;background:#222;color:#ddd;font:14px sans-serif;text-align:center}
img{max-width:100vw;max-height:92vh}#s{padding:6px}</style></head>
<body><div id="s">jaxmocap live</div><img src="/stream.mjpg__QUERY__" alt="live overlay">
<script>
async function tick(){try{const s=await (await fetch('/stats.json__QUERY__')).json();
document.getElementById('s').textContent=`${s.fps.toFixed(1)} frames/s, latency ${s.latency_ms.toFixed(0)} ms, `+
`${s.dropped} dropped, `+('hands' in s?`${s.hands} hands`:`${s.people} people`);}catch(e){}}
setInterval(tick,1000);
</script></body></html>
"""
BOUNDARY = "jaxmocapframe"
MAX_VIEWERS = 8  # streams at once, each a thread and a socket (a page is one)
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")
WILDCARDS = ("0.0.0.0", "::", "")


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or an address) is this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class Viewer:
    """Serves the page on ``host:port`` (port 0: any free one; `port` says which, `url` where to watch) until
    `close`, to the requests the module docstring admits."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8080, timeout: float = 5.0,
                 max_viewers: int = MAX_VIEWERS):
        self.host = host
        self.token = None if is_loopback(host) else secrets.token_urlsafe(16)
        self._streams = threading.BoundedSemaphore(max_viewers)
        self._changed = threading.Condition()
        self._jpeg, self._count, self._closed, self._waiting = None, 0, False, 0
        self.stats = {"fps": 0.0, "latency_ms": 0.0, "dropped": 0, "solved": 0, "people": 0}

        class Handler(_Handler):
            pass

        Handler.viewer, Handler.timeout = self, timeout
        self.server = ThreadingHTTPServer((host, port), Handler)
        self.server.daemon_threads = True
        self.port = self.server.server_address[1]
        named = f"[{host}]" if ":" in host else host
        self._hosts = None if host in WILDCARDS else {f"{name}:{self.port}".lower() for name in (
            LOOPBACK_NAMES if is_loopback(host) else ()) + (named,)}
        self._thread = threading.Thread(target=self.server.serve_forever, name="jaxmocap-viewer", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        """Where to watch: the page's address, with its token when it has one."""
        shown = "127.0.0.1" if self.host in WILDCARDS else f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{shown}:{self.port}/" + self.query

    @property
    def query(self) -> str:
        return "" if self.token is None else f"?token={self.token}"

    def admits(self, host_header: str | None, query: str) -> bool:
        """Whether a request with this ``Host`` header and query string may be answered."""
        if self._hosts is not None and (host_header or "").strip().lower() not in self._hosts:
            return False
        if self.token is None:
            return True
        given = parse_qs(query).get("token", [""])[0]
        return hmac.compare_digest(given.encode(), self.token.encode())

    def take_stream(self) -> bool:
        """One of the `max_viewers` streams' places (False: all taken); `give_stream` gives it back."""
        return self._streams.acquire(blocking=False)

    def give_stream(self) -> None:
        self._streams.release()

    def publish(self, jpeg: bytes, stats: dict | None = None) -> None:
        """The newest frame (JPEG bytes) and rates; returns at once."""
        with self._changed:
            self._jpeg, self._count = jpeg, self._count + 1
            self.stats = stats or self.stats
            self._changed.notify_all()

    def wanted(self) -> bool:
        """Whether a viewer is waiting for a frame newer than the newest published."""
        with self._changed:
            return self._waiting > 0

    def frame_after(self, count: int, timeout: float) -> tuple[int, bytes | None]:
        """The first frame published after the ``count``-th (waiting at most ``timeout`` s, `wanted` meanwhile):
        ``(its count, JPEG)``; ``None`` when closed or timed out."""
        with self._changed:
            self._waiting += 1
            try:
                self._changed.wait_for(lambda: self._count > count or self._closed, timeout)
            finally:
                self._waiting -= 1
            return self._count, None if self._closed or self._count <= count else self._jpeg

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        if self._closed:
            return
        with self._changed:
            self._closed = True
            self._changed.notify_all()
        self.server.shutdown()
        self.server.server_close()


class _Handler(BaseHTTPRequestHandler):
    viewer: Viewer

    def log_message(self, *args) -> None:  # quiet: the live line says what matters
        pass

    def do_GET(self) -> None:
        path, _, query = self.path.partition("?")
        if not self.viewer.admits(self.headers.get("Host"), query):
            self._send(403, "text/plain", b"")
        elif path == "/":
            self._send(200, "text/html; charset=utf-8", PAGE.replace("__QUERY__", self.viewer.query).encode())
        elif path == "/stats.json":
            self._send(200, "application/json", json.dumps(self.viewer.stats).encode())
        elif path == "/stream.mjpg":
            self._stream()
        else:
            self._send(404, "text/plain", b"not found\n")

    def _send(self, status: int, kind: str, body: bytes) -> None:
        self.send_response(status)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def _stream(self) -> None:
        if not self.viewer.take_stream():
            self._send(503, "text/plain", b"")
            return
        try:
            self._frames()
        finally:
            self.viewer.give_stream()

    def _frames(self) -> None:
        self.send_response(200)
        self.send_header("Content-Type", f"multipart/x-mixed-replace; boundary={BOUNDARY}")
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        count = 0
        try:
            while True:
                count, jpeg = self.viewer.frame_after(count, self.timeout)
                if jpeg is None:
                    if self.viewer.closed:
                        return
                    continue
                self.wfile.write(f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len(jpeg)}\r\n\r\n"
                                 .encode() + jpeg + b"\r\n")
        except OSError:  # the viewer went away, or stopped reading for longer than the timeout
            return
