#!/usr/bin/env python3
"""Declaration lines per node file: everything a node costs besides `run` and its helpers.

Counted: code lines (not blank, not comments or doc comments, not `use`, not lines holding
only closing brackets) of
  - old API: the `node_doc!` block, the `XParams` struct and `impl Params`, the enums and
    constants that `impl Params` names, and `impl Node` up to the `fn run` line;
  - new API: the `params!` block or the `#[derive(Params)]` struct, `#[derive(ParamEnum)]`
    enums, `inputs!` / `outputs!`, and the `#[node]` impl up to the `fn run` line, of which
    `fn memory` counts its signature only (its body is computed, like `run`'s);
plus the `pub mod` line that declares the node's file (registration is found by build.rs;
before that, a `reg.add` line per node made it 2: `--rev` of an older commit counts 2).

Usage: decl_lines.py [--rev GITREV] [--max N]  (every node file under nodes/)
Prints one line per node file and the median and max; with --max, exits 1 when a node takes
more than N lines (CI runs it so, with the maximum ARCHITECTURE.md states).
"""
import re, subprocess, sys, statistics

def strip_literals(line):
    line = re.sub(r'"(\\.|[^"\\])*"', '""', line)
    line = re.sub(r"'(\\.|[^'\\])'", "''", line)
    return line

def items(lines):
    """Top-level items as (first, last) line indexes, attributes and docs included."""
    out, depth, start = [], 0, None
    for i, raw in enumerate(lines):
        l = strip_literals(raw.split('//')[0] if not raw.lstrip().startswith('///') else '')
        if depth == 0 and start is None and raw.strip() and not raw.startswith((' ', '}')):
            start = i
        depth += l.count('{') + l.count('(') + l.count('[') - l.count('}') - l.count(')') - l.count(']')
        if depth == 0 and start is not None and (raw.rstrip().endswith(('}', ';', '})', ');')) or raw.startswith('}')):
            out.append((start, i))
            start = None
    return out

def is_code(l):
    s = l.strip()
    closing = re.fullmatch(r'[})\]]+[;,]?', s)
    return bool(s) and not closing and not s.startswith('//') and not s.startswith('use ') and not s.startswith('pub use ')

def count_until_run(lines, a, b):
    """Lines of an impl block up to the `fn run` signature (for a sharded node, the first of
    `fn shard`, `fn run_items` and `fn gather`: its algorithm), plus the closing brace."""
    n = 0
    i = a
    while i <= b:
        if is_code(lines[i]):
            n += 1
        if re.search(r'\bfn memory\b', lines[i]):
            # The estimate is computed, like `run`: its signature is declaration, its body
            # is not.
            j = i
            while not lines[j].rstrip().endswith('{'):
                j += 1
                n += is_code(lines[j])
            depth = 0
            for k in range(j, b + 1):
                l = strip_literals(lines[k].split('//')[0])
                depth += l.count('{') - l.count('}')
                if depth == 0:
                    break
            i = k + 1
            continue
        if re.search(r'\bfn (run|shard|run_items|gather)\b', lines[i]):
            # the signature may wrap over several lines
            j = i
            while not lines[j].rstrip().endswith('{'):
                j += 1
                n += is_code(lines[j])
            return n
        i += 1
    return n

def measure(text, registration):
    lines = text.split('\n')
    if '#[cfg(test)]' in text:
        lines = lines[:lines.index(next(l for l in lines if l.startswith('#[cfg(test)]')))]
    its = items(lines)
    body = lambda a, b: '\n'.join(lines[a:b + 1])
    total = 0
    params_block = ''
    for a, b in its:
        t = body(a, b)
        if re.search(r'impl Params for', t):
            params_block += t
    named = set(re.findall(r'\b([A-Z][A-Za-z0-9_]*)\b', params_block))
    for a, b in its:
        t = body(a, b)
        code = sum(1 for l in lines[a:b + 1] if is_code(l))
        head = '\n'.join(l for l in lines[a:b + 1] if not l.lstrip().startswith('///'))
        if 'node_doc!' in head or re.match(r'(pub )?params! \{', head.strip()) or 'impl Params for' in head or 'derive(Params' in head or 'derive(Clone, Copy, Debug, PartialEq, ParamEnum' in head \
                or 'ParamEnum)' in head or re.match(r'\s*(pub )?(inputs|outputs)!', head.strip().split('\n')[0]):
            total += code
        elif re.search(r'impl Node for|#\[node', head):
            total += count_until_run(lines, a, b)
        elif re.match(r'(pub )?struct (\w+Params)\b', head.strip().split('\n')[-1] if False else head.strip()) or re.search(r'^(pub )?struct \w+Params\b', head, re.M):
            total += code
        else:
            m = re.search(r'^(?:pub )?(?:enum|const) ([A-Z][A-Za-z0-9_]*)', head, re.M)
            if m and m.group(1) in named and 'impl' not in head.split('\n')[0]:
                total += code
    return total + registration

def node_files(rev):
    if rev:
        names = subprocess.run(['git', 'ls-tree', '-r', '--name-only', rev, 'nodes'], capture_output=True, text=True).stdout.split()
        get = lambda f: subprocess.run(['git', 'show', f'{rev}:{f}'], capture_output=True, text=True).stdout
    else:
        names = subprocess.run(['git', 'ls-files', '--cached', '--others', '--exclude-standard', 'nodes'], capture_output=True, text=True).stdout.split()
        get = lambda f: open(f).read()
    for f in sorted(names):
        if f.endswith('.rs'):
            t = get(f)
            if 'impl Node for' in t or '#[node(' in t:
                yield f, t

def main():
    args = sys.argv[1:]
    rev = None
    limit = None
    while args:
        if args[:1] == ['--rev']:
            rev, args = args[1], args[2:]
        elif args[:1] == ['--max']:
            limit, args = int(args[1]), args[2:]
        else:
            sys.exit(f'decl_lines.py: unknown argument {args[0]}')
    counts = []
    registration = 2 if rev and subprocess.run(['git', 'cat-file', '-e', f'{rev}:core/build/src/lib.rs'], capture_output=True).returncode else 1
    for f, t in node_files(rev):
        n = measure(t, registration)
        counts.append(n)
        print(f'{n:4}  {f}')
    print(f'nodes {len(counts)}, median {statistics.median(counts)}, max {max(counts)}, total {sum(counts)}')
    if limit is not None and max(counts) > limit:
        sys.exit(f'a node takes {max(counts)} declaration lines, over the maximum of {limit}')

main()
