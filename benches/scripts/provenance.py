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


def cells(threads=None):
    """The four provenance cells; `threads` defaults to the machine's core count."""
    cores = os.cpu_count()
    return [time.strftime("%Y-%m-%d", time.gmtime()), f"{platform.machine()} {sys.platform} with {cores} cores",
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
