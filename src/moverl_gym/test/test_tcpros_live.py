"""The shield's ~step speaks TCPROS itself (moverl_tcpros, src/moverl_tcpros): what any ROS client does with a service
works on it (launches its own graph on a free port).

Each case talks to /shield/step the way a client library does, on raw sockets where the library would hide what is
checked: a probe (rosservice, wait_for_service) gets the service's type; a wrong MD5 sum is refused with an error
header; a request cut short and a corrupt length are dropped without harming the node; non-persistent clients (rospy,
`rosservice call`) are answered once; `persistent=true` keeps the connection. After all that, the env steps as before.
"""

import socket
import struct

import gymnasium as gym
import numpy as np
import pytest

import moverl_gym  # noqa: F401

pytestmark = pytest.mark.quick

SERVICE = "/shield/step"


def _header(fields: dict) -> bytes:
    body = b"".join(struct.pack("<I", len(kv)) + kv for kv in (f"{k}={v}".encode() for k, v in fields.items()))
    return struct.pack("<I", len(body)) + body


def _read_exact(sock, n: int) -> bytes:
    out = b""
    while len(out) < n:
        chunk = sock.recv(n - len(out))
        if not chunk:
            raise ConnectionError(f"closed after {len(out)} of {n} bytes")
        out += chunk
    return out


def _read_header(sock) -> dict:
    (size,) = struct.unpack("<I", _read_exact(sock, 4))
    data, fields = _read_exact(sock, size), {}
    while data:
        (n,) = struct.unpack("<I", data[:4])
        key, _, value = data[4 : 4 + n].decode().partition("=")
        fields[key] = value
        data = data[4 + n :]
    return fields


def _connect():
    import rospy.core
    import rosservice

    uri = rosservice.get_service_uri(SERVICE)
    assert uri and uri.startswith("rosrpc://"), uri
    host, port = rospy.core.parse_rosrpc_uri(uri)
    return socket.create_connection((host, port), timeout=5)


def _request(srv_type, target, duration=0.05) -> bytes:
    import io

    req = srv_type._request_class(target=list(target), duration=duration, not_after=0.0)
    buf = io.BytesIO()
    req.serialize(buf)
    return struct.pack("<I", len(buf.getvalue())) + buf.getvalue()


def _answer(sock, srv_type):
    ok = _read_exact(sock, 1)[0]
    (n,) = struct.unpack("<I", _read_exact(sock, 4))
    payload = _read_exact(sock, n)
    if ok != 1:
        return ok, payload.decode(errors="replace")
    res = srv_type._response_class()
    res.deserialize(payload)
    return ok, res


@pytest.fixture(scope="module")
def env():
    env = gym.make("MoveRL/PandaReachTable-v0")
    env.reset(seed=0)
    yield env
    env.close()


def test_probe_gives_the_type(env):
    from moverl_msgs.srv import ShieldStep

    with _connect() as s:
        s.sendall(_header({"callerid": "/probe", "service": SERVICE, "md5sum": "*", "probe": "1"}))
        h = _read_header(s)
        assert h["md5sum"] == ShieldStep._md5sum and h["type"] == ShieldStep._type, h
        assert h["request_type"] == ShieldStep._request_class._type, h
        assert s.recv(1) == b""  # a probe is answered and closed


def test_wrong_md5_and_wrong_service_are_refused(env):
    with _connect() as s:
        s.sendall(_header({"callerid": "/x", "service": SERVICE, "md5sum": "0" * 32, "persistent": "1"}))
        h = _read_header(s)
        assert "md5sums do not match" in h.get("error", ""), h
    with _connect() as s:
        s.sendall(_header({"callerid": "/x", "service": "/elsewhere", "md5sum": "*"}))
        assert "error" in _read_header(s)


def test_persistent_true_cut_short_and_corrupt_lengths(env):
    from moverl_msgs.srv import ShieldStep

    q = np.asarray(env.unwrapped.q, dtype=float)
    # persistent=true (what roscpp and rospy also accept): two answers on one connection.
    with _connect() as s:
        s.sendall(_header({"callerid": "/x", "service": SERVICE, "md5sum": ShieldStep._md5sum, "persistent": "true"}))
        assert "error" not in _read_header(s)
        for _ in range(2):
            s.sendall(_request(ShieldStep, q))
            ok, res = _answer(s, ShieldStep)
            assert ok == 1 and res.verdict == res.SAFE, res
    # A request cut short (the client leaves) and a corrupt 4 GB length: the connection is dropped, nothing else.
    with _connect() as s:
        s.sendall(_header({"callerid": "/x", "service": SERVICE, "md5sum": "*", "persistent": "1"}))
        _read_header(s)
        s.sendall(_request(ShieldStep, q)[:10])
    with _connect() as s:
        s.sendall(_header({"callerid": "/x", "service": SERVICE, "md5sum": "*", "persistent": "1"}))
        _read_header(s)
        s.sendall(struct.pack("<I", 0xFFFFFFF0) + b"\0" * 16)
        try:
            assert s.recv(1) == b""  # closed, no answer
        except ConnectionResetError:
            pass  # closed with our bytes unread (the kernel then resets): dropped too


def test_non_persistent_rospy_client_and_the_env_after(env):
    import rospy

    from moverl_msgs.srv import ShieldStep

    q = [float(x) for x in env.unwrapped.q]
    call = rospy.ServiceProxy(SERVICE, ShieldStep)  # non-persistent: one connection per call, as `rosservice call`
    for _ in range(2):
        res = call(target=q, duration=0.05, not_after=0.0)
        assert res.verdict == res.SAFE, res.message
    # A request with the wrong number of joints is answered with a verdict, not an error.
    assert call(target=q[:-1], duration=0.05, not_after=0.0).verdict == ShieldStep._response_class.INVALID_REQUEST
    # The env's own persistent connection still steps.
    for _ in range(5):
        _, _, term, trunc, info = env.step(np.zeros(7, dtype=np.float32))
        assert info["verdict"] == "safe" and info["contacts"] == 0, info
