"""Ctrl-C during a long run: the run is cancelled, Python gets KeyboardInterrupt, and the
disk cache holds nothing half-written (a second run from the same cache completes)."""

import signal
import subprocess
import sys
import time

import relume

SLOW = """Graph(
    version: 1,
    nodes: {
        "noisy": (kind: "TestPattern", params: (width: 2048, height: 2048, pattern: Constant, color: (0.5, 0.5, 0.5), noise: 0.4, seed: 1)),
        "median": (kind: "MedianFilter", params: (radius: 16)),
    },
    edges: [("noisy.image", "median.image")],
    outputs: {"image": "median.image"},
)
"""

SCRIPT = """
import signal, sys, relume
# Ctrl-C as in a terminal: a process started from a background job inherits SIGINT ignored,
# and Python then installs no handler for it.
signal.signal(signal.SIGINT, signal.default_int_handler)
g = relume.Graph.load(sys.argv[1], cache=sys.argv[2])
started = False
def progress(node, fraction):
    global started
    if node == "median" and not started:
        started = True
        print("median started", flush=True)
g.run(progress=progress)
print("finished", flush=True)
"""


def test_ctrl_c_cancels_the_run_and_raises_keyboard_interrupt(tmp_path):
    graph, cache = tmp_path / "slow.ron", tmp_path / "cache"
    graph.write_text(SLOW)
    p = subprocess.Popen([sys.executable, "-c", SCRIPT, str(graph), str(cache)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "median started"
    time.sleep(0.3)
    t0 = time.monotonic()
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert p.returncode != 0 and "KeyboardInterrupt" in err, (out, err)
    assert "finished" not in out
    assert time.monotonic() - t0 < 10, "the run stopped soon after Ctrl-C"
    assert not [f for f in cache.rglob("*") if f.is_file() and ".tmp" in f.name], "nothing half-written"
    # The cache is usable: the same graph runs to its end from it.
    g = relume.Graph.load(graph, cache=cache)
    g.set("median.radius", 1)
    assert g.run().images["image"].shape == (2048, 2048, 3)
