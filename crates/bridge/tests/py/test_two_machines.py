"""Two machines: two private network namespaces joined by a veth pair, the bridge in one
and a Zenoh peer in the other, over TCP on the pair's addresses. The peer reads joint
states, arms, and its commands move the simulated robot."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from bridgekit import ROOT, Bridge

A, B = f"rbb-a{os.getpid()}", f"rbb-b{os.getpid()}"
ADDR_A, ADDR_B = "10.231.0.1", "10.231.0.2"


def ip(*args: str, ns: str | None = None) -> None:
    cmd = ["ip", *(["-n", ns] if ns else []), *args]
    subprocess.run(cmd, check=True, capture_output=True)


@pytest.fixture(scope="module")
def machines():
    ip("netns", "add", A)
    ip("netns", "add", B)
    try:
        ip("link", "add", "veth-a", "netns", A, "type", "veth", "peer", "veth-b", "netns", B)
        for ns, dev, addr in [(A, "veth-a", ADDR_A), (B, "veth-b", ADDR_B)]:
            ip("addr", "add", f"{addr}/24", "dev", dev, ns=ns)
            ip("link", "set", dev, "up", ns=ns)
            ip("link", "set", "lo", "up", ns=ns)
        yield
    finally:
        subprocess.run(["ip", "netns", "del", A], check=False)
        subprocess.run(["ip", "netns", "del", B], check=False)


PEER = textwrap.dedent("""
    import json, math, sys, time
    sys.path.insert(0, {path!r})
    from bridgekit import Inbox, command, joint_state, query, session, sim, whj_deg
    s = session({endpoint!r})
    st = joint_state(Inbox(s, "joint_states").get(20))
    names = list(st.name)
    t = [float(p) for p in st.position]
    t[names.index("j4")] += 0.2
    want = math.degrees(t[names.index("j4")])
    before = whj_deg(sim(s), 4)
    query(s, "robobus/arm", "true")
    pub = s.declare_publisher("joint_commands")
    end = time.monotonic() + 10
    while time.monotonic() < end and abs(whj_deg(sim(s), 4) - want) > 0.3:
        for _ in range(10):
            pub.put(command(t))
            time.sleep(0.01)
    after = whj_deg(sim(s), 4)
    print(json.dumps({{"names": names, "before": before, "after": after, "want": want}}))
    s.close()
""")


def test_a_peer_on_another_machine_reads_and_commands_over_tcp(machines):
    endpoint = f"tcp/{ADDR_A}:7447"
    bridge = Bridge("--rate", "50", host=ADDR_A, port=7447, prefix=["ip", "netns", "exec", A])
    try:
        assert endpoint in bridge.first
        code = PEER.format(path=str(ROOT / "crates/bridge/tests/py"), endpoint=endpoint)
        out = subprocess.run(["ip", "netns", "exec", B, sys.executable, "-c", code],
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr
        r = json.loads(out.stdout.strip().splitlines()[-1])
        assert r["names"][-1] == "j7" and len(r["names"]) == 23
        assert abs(r["after"] - r["want"]) < 0.3 and abs(r["before"] - r["want"]) > 5, r
        # The bridge listens on its machine's address only: from the other machine, the
        # loopback default of a bridge is not reachable (nothing listens on B's 7447).
        probe = subprocess.run(["ip", "netns", "exec", B, sys.executable, "-c",
                                "import socket; socket.create_connection(('10.231.0.2', 7447), 2)"],
                               capture_output=True, text=True)
        assert probe.returncode != 0
    finally:
        assert bridge.stop() == 0
