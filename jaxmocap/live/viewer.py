"""The live view: a local web page with the newest overlay frame (an MJPEG stream) and the current rates.

It serves three paths only, ``/`` (the page), ``/stream.mjpg`` and ``/stats.json``; anything else is a 404, and
no path reaches the file system. Each viewer has its own thread: `publish` only swaps the newest frame in, so a
slow viewer misses frames and a vanished one times out; capture never waits for either."""

import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>jaxmocap live</title>
<style>body{margin:0;background:#222;color:#ddd;font:14px sans-serif;text-align:center}
img{max-width:100vw;max-height:92vh}#s{padding:6px}</style></head>
<body><div id="s">jaxmocap live</div><img src="/stream.mjpg" alt="live overlay">
<script>
async function tick(){try{const s=await (await fetch('/stats.json')).json();
document.getElementById('s').textContent=`${s.fps.toFixed(1)} frames/s, latency ${s.latency_ms.toFixed(0)} ms, `+
`${s.dropped} dropped, `+('hands' in s?`${s.hands} hands`:`${s.people} people`);}catch(e){}}
setInterval(tick,1000);
</script></body></html>
"""
BOUNDARY = "jaxmocapframe"


class Viewer:
    """Serves the page on ``host:port`` (port 0: any free one; `port` says which) until `close`."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8080, timeout: float = 5.0):
        self._changed = threading.Condition()
        self._jpeg, self._count, self._closed = None, 0, False
        self.stats = {"fps": 0.0, "latency_ms": 0.0, "dropped": 0, "solved": 0, "people": 0}

        class Handler(_Handler):
            pass

        Handler.viewer, Handler.timeout = self, timeout
        self.server = ThreadingHTTPServer((host, port), Handler)
        self.server.daemon_threads = True
        self.port = self.server.server_address[1]
        self._thread = threading.Thread(target=self.server.serve_forever, name="jaxmocap-viewer", daemon=True)
        self._thread.start()

    def publish(self, jpeg: bytes, stats: dict | None = None) -> None:
        """The newest frame (JPEG bytes) and rates; returns at once."""
        with self._changed:
            self._jpeg, self._count = jpeg, self._count + 1
            self.stats = stats or self.stats
            self._changed.notify_all()

    def frame_after(self, count: int, timeout: float) -> tuple[int, bytes | None]:
        """The first frame published after the ``count``-th (waiting at most ``timeout`` s): ``(its count,
        JPEG)``; ``None`` when closed or timed out."""
        with self._changed:
            self._changed.wait_for(lambda: self._count > count or self._closed, timeout)
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
        path = self.path.split("?", 1)[0]
        if path == "/":
            self._send(200, "text/html; charset=utf-8", PAGE.encode())
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
