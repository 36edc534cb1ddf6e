"""A minimal RTSP server for the stream tests: ffmpeg makes the RTP packets, this answers the RTSP.

ffmpeg can publish to an RTSP server or receive from a publisher (``-rtsp_flags listen``), but it
cannot itself answer a player such as OpenCV's capture (DESCRIBE, SETUP, PLAY). So the tests run
``ffmpeg -f rtp`` (Motion-JPEG in RTP, RFC 2435, payload type 26) to two local UDP ports, and this
relay answers a player's RTSP requests on a TCP port and forwards each RTP (channel 0) and RTCP
(channel 1) packet to the player interleaved on its RTSP connection (``$``, channel, length), the
transport OpenCV asks for (RTP/AVP/TCP). Only what a player needs: OPTIONS, DESCRIBE, SETUP
(interleaved), PLAY, GET_PARAMETER, TEARDOWN; one media stream. ``stop()`` closes every socket, as a
camera that goes away.
"""

from __future__ import annotations

import socket
import struct
import threading

SDP = (
    "v=0\r\no=- 0 0 IN IP4 127.0.0.1\r\ns=mcit test stream\r\nc=IN IP4 0.0.0.0\r\nt=0 0\r\n"
    "a=control:*\r\nm=video 0 RTP/AVP 26\r\na=control:trackID=0\r\n"
)


class RtspRelay:
    """RTSP on 127.0.0.1:``port`` (path ``/live``); RTP received on UDP ``rtp_port``, RTCP on ``rtp_port + 1``."""

    def __init__(self, port: int, rtp_port: int):
        self.port, self.rtp_port = port, rtp_port
        self.url = f"rtsp://127.0.0.1:{port}/live"
        self._lock = threading.Lock()
        self._players: list[socket.socket] = []
        self._sockets: list[socket.socket] = []
        self._stop = threading.Event()

    def start(self) -> RtspRelay:
        listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(("127.0.0.1", self.port))
        listener.listen(4)
        self._sockets.append(listener)
        threading.Thread(target=self._accept, args=(listener,), daemon=True).start()
        for channel in (0, 1):
            udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            udp.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            udp.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)  # a busy machine: keep ffmpeg's packets
            udp.bind(("127.0.0.1", self.rtp_port + channel))
            self._sockets.append(udp)
            threading.Thread(target=self._forward, args=(udp, channel), daemon=True).start()
        return self

    def stop(self) -> None:
        self._stop.set()
        with self._lock:
            sockets = self._sockets + self._players
            self._players = []
        for sock in sockets:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()

    def _accept(self, listener: socket.socket) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = listener.accept()
            except OSError:
                return
            with self._lock:
                self._sockets.append(conn)
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _forward(self, udp: socket.socket, channel: int) -> None:
        while not self._stop.is_set():
            try:
                packet = udp.recv(65536)
            except OSError:
                return
            data = b"$" + struct.pack(">BH", channel, len(packet)) + packet
            with self._lock:
                players = list(self._players)
            for player in players:
                try:
                    player.sendall(data)
                except OSError:
                    with self._lock:
                        if player in self._players:
                            self._players.remove(player)

    def _serve(self, conn: socket.socket) -> None:
        buffer = b""
        while not self._stop.is_set():
            while b"\r\n\r\n" not in buffer:
                try:
                    chunk = conn.recv(4096)
                except OSError:
                    return
                if not chunk:
                    return
                buffer += chunk
                while buffer.startswith(b"$") and len(buffer) >= 4:  # the player's RTCP reports: skipped
                    size = struct.unpack(">H", buffer[2:4])[0]
                    if len(buffer) < 4 + size:
                        break
                    buffer = buffer[4 + size :]
            head, buffer = buffer.split(b"\r\n\r\n", 1)
            lines = head.decode("latin-1").split("\r\n")
            method = lines[0].split(" ")[0]
            headers = {k.strip().lower(): v.strip() for k, _, v in (line.partition(":") for line in lines[1:])}
            body_len = int(headers.get("content-length", "0"))
            buffer = buffer[body_len:]
            reply = ["RTSP/1.0 200 OK", f"CSeq: {headers.get('cseq', '0')}"]
            body = ""
            if method == "OPTIONS":
                reply.append("Public: OPTIONS, DESCRIBE, SETUP, PLAY, GET_PARAMETER, TEARDOWN")
            elif method == "DESCRIBE":
                reply += [f"Content-Base: {self.url}/", "Content-Type: application/sdp"]
                body = SDP
            elif method == "SETUP":
                transport = headers.get("transport", "")
                if "TCP" not in transport.upper():
                    reply = ["RTSP/1.0 461 Unsupported Transport", f"CSeq: {headers.get('cseq', '0')}"]
                else:
                    reply += ["Transport: RTP/AVP/TCP;unicast;interleaved=0-1", "Session: 4242;timeout=60"]
            elif method == "PLAY":
                reply += ["Session: 4242", "Range: npt=0.000-"]
            elif method in ("GET_PARAMETER", "TEARDOWN"):
                reply.append("Session: 4242")
            else:
                reply = ["RTSP/1.0 501 Not Implemented", f"CSeq: {headers.get('cseq', '0')}"]
            if body:
                reply.append(f"Content-Length: {len(body)}")
            try:
                conn.sendall(("\r\n".join(reply) + "\r\n\r\n" + body).encode("latin-1"))
            except OSError:
                return
            if method == "PLAY":
                with self._lock:
                    self._players.append(conn)
            elif method == "TEARDOWN":
                with self._lock:
                    if conn in self._players:
                        self._players.remove(conn)
                return
