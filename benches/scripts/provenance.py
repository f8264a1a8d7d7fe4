"""The provenance every results file in docs/results/ ends its rows with, in the form
`relume sweep` writes it: the date (UTC), the machine, the threads, and the commit measured
(12 hex digits, `-dirty` when tracked files differ from it, `unknown` outside a git checkout)."""
import csv
import os
import platform
import subprocess
import sys
import time

COLUMNS = ["date", "machine", "threads", "commit"]


def commit():
    try:
        head = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True).stdout.strip()
        return head + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def widest_simd():
    """The widest x86 vector extension /proc/cpuinfo reports, as the Rust side names it, or None."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            flags = next((line.split(":", 1)[1].split() for line in f if line.startswith("flags")), [])
    except OSError:
        return None
    if platform.machine() != "x86_64":
        return None
    return "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "SSE2"


def cells(threads=None):
    """The four provenance cells; `threads` defaults to the machine's core count."""
    cores = os.cpu_count()
    simd = widest_simd()
    return [time.strftime("%Y-%m-%d", time.gmtime()), f"{platform.machine()} {sys.platform} with {cores} cores" + (f" ({simd})" if simd else ""),
            str(threads or cores), commit()]


def append_rows(path, header, rows):
    """Appends `rows` to the results CSV at `path`, writing `header` first where the file is new."""
    new = not os.path.exists(path)
    with open(path, "a", newline="", encoding="utf-8") as f:
        w = csv.writer(f, lineterminator="\n")
        if new:
            w.writerow(header)
        w.writerows(rows)
    print(f"appended {len(rows)} rows to {path}")
