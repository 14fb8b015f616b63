"""A stand-in for an Ouster sensor's HTTP API, serving one metadata JSON the way the sensor
does (`/api/v1/sensor/metadata/sensor_info`, then `/api/v1/sensor/metadata`), for the
tests of fetching metadata from a live sensor. Run as a script (the SDK's HTTP client holds
the GIL while it waits, so the server must be another process):

    python tests/bridge/ouster_http.py METADATA.json    # prints its port, serves until killed
"""

from __future__ import annotations

import http.server
import json
import socketserver
import sys

FIRMWARE = "ousteros-image-prod-aries-v3.1.0+20240101000000"  # what a sensor reports


def serve(path: str) -> None:
    text = open(path).read()
    sensor_info = dict(json.loads(text)["sensor_info"])
    sensor_info["image_rev"] = sensor_info.get("image_rev") or FIRMWARE

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 - the library's name
            route = self.path.rstrip("/")
            if route.endswith("/api/v1/sensor/metadata/sensor_info"):
                body = json.dumps(sensor_info).encode()
            elif route.endswith("/api/v1/sensor/metadata"):
                body = text.encode()
            else:
                self.send_response(404)
                self.end_headers()
                return
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):
            pass

    with socketserver.TCPServer(("127.0.0.1", 0), Handler) as server:
        print(server.server_address[1], flush=True)
        server.serve_forever()


if __name__ == "__main__":
    serve(sys.argv[1])
