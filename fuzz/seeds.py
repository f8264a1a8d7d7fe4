#!/usr/bin/env python3
"""Seed corpora for the cache_entry and port_decode fuzz targets, from real cache entries.

Runs `relume run GRAPH --cache-all --cache DIR --report R` for each graph given (at the sizes
given with --set), then for every node in the report reads its entry and writes, where at most 32 KiB,
  corpus/cache_entry/seed-KIND-N:  KIND, a line break, the entry's body (without the magic
                                    and key before it and the checksum after it);
  corpus/port_decode/seed-TYPE-N:  TYPE, a line break, one output's payload.

Usage (from fuzz/): seeds.py RELUME GRAPH [--set node.param=value]... [GRAPH ...]
"""
import json, os, struct, subprocess, sys, tempfile

MAGIC = b"RELUMEC3"
MAX_SEED = 32 << 10


def parse_entry(b):
    """(body, [(type, payload)]) of an entry file."""
    assert b[:8] == MAGIC, "not a relume cache entry"
    body = b[40:-32]
    at = 40

    def u32():
        nonlocal at
        v = struct.unpack_from("<I", b, at)[0]
        at += 4
        return v

    def u64():
        nonlocal at
        v = struct.unpack_from("<Q", b, at)[0]
        at += 8
        return v

    def s():
        nonlocal at
        n = u32()
        v = b[at:at + n].decode()
        at += n
        return v

    heads = []
    for _ in range(u32()):
        _name, ty = s(), s()
        at += 32
        heads.append((ty, u64()))
    for _ in range(u32()):
        s(), u64()
    for _ in range(u32()):
        s()
    for _ in range(u32()):
        s()
        at += 32
    u64()
    payloads = []
    for ty, n in heads:
        payloads.append((ty, b[at:at + n]))
        at += n
    return body, payloads


def main():
    relume, rest = sys.argv[1], sys.argv[2:]
    runs, cur = [], None
    while rest:
        if rest[0] == "--set":
            cur[1].extend(rest[:2])
            rest = rest[2:]
        else:
            cur = (rest[0], [])
            runs.append(cur)
            rest = rest[1:]
    os.makedirs("corpus/cache_entry", exist_ok=True)
    os.makedirs("corpus/port_decode", exist_ok=True)
    written = 0
    with tempfile.TemporaryDirectory() as tmp:
        for k, (graph, sets) in enumerate(runs):
            cache, report = os.path.join(tmp, f"c{k}"), os.path.join(tmp, f"r{k}.json")
            subprocess.run([relume, "run", graph, "--cache-all", "--cache", cache, "--report", report, "--out", os.path.join(tmp, f"o{k}"), "-q"] + sets, check=True)
            for node in json.load(open(report))["nodes"]:
                key = node.get("key")
                path = key and os.path.join(cache, key[:2], key + ".rlc")
                if not path or not os.path.isfile(path):
                    continue
                body, payloads = parse_entry(open(path, "rb").read())
                # Seeds stay small: the fuzzer mutates small inputs faster, and the corpus is
                # kept in the repository.
                if len(body) <= MAX_SEED:
                    open(f"corpus/cache_entry/seed-{node['kind']}-{k}", "wb").write(node["kind"].encode() + b"\n" + body)
                    written += 1
                for j, (ty, p) in enumerate(payloads):
                    if len(p) <= MAX_SEED:
                        open(f"corpus/port_decode/seed-{ty}-{k}-{j}", "wb").write(ty.encode() + b"\n" + p)
                        written += 1
    print(f"{written} seeds written")


if __name__ == "__main__":
    main()
