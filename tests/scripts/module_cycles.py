#!/usr/bin/env python3
"""Finds import circles between the modules of each crate of the workspace, and fails on any.

A module is a file (or an inline `mod x { … }` that is not a test module). Module A depends on
module B when A's non-test code names an item that B defines: through `use`, or through a path
(`crate::…`, `super::…`, `self::…`, a path from a `use`d module). A name that a module only
re-exports (`pub use child::Item`) is followed to the module that defines it, as the compiler
resolves it. A re-export names an item for the module's users without using it, so it is not a
dependency of the re-exporting module (a `mod.rs` that declares its children and re-exports
their items depends on none of them); a module never depends on itself, and declaring a child
(`mod child;`) is not a dependency. The strongly
connected components of that graph with more than one module are the circles; each is printed
with one path through it and the line that makes each step.

It also holds the nodes' rule: a module that defines a node (`#[node(…)]`) depends on no other
module that defines one. What two nodes share lives in a module that is not a node.

usage: module_cycles.py [CRATE_DIR ...]   (default: every workspace member with a src/)
       module_cycles.py --self-test       (checks itself on small crates made in a temp folder)
Exit 0 without circles, 1 with.
"""
import os
import re
import sys
import tempfile

IDENT = r'[A-Za-z_][A-Za-z0-9_]*'


def strip_comments_and_strings(text):
    """Blanks comments, string and char literals (keeps line breaks, so line numbers hold)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith('//', i):
            j = text.find('\n', i)
            j = n if j < 0 else j
            out.append(' ' * (j - i))
            i = j
        elif text.startswith('/*', i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith('/*', j):
                    depth, j = depth + 1, j + 2
                elif text.startswith('*/', j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(re.sub(r'[^\n]', ' ', text[i:j]))
            i = j
        elif re.match(r'b?r(#*)"', text[i:i + 20]):
            m = re.match(r'b?r(#*)"', text[i:])
            end = '"' + m.group(1)
            j = text.find(end, i + m.end())
            j = n if j < 0 else j + len(end)
            out.append(re.sub(r'[^\n]', ' ', text[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == '\\' else 1
            j += 1
            out.append(re.sub(r'[^\n]', ' ', text[i:j]))
            i = j
        elif c == "'" and re.match(r"'(\\.|[^\\'])'", text[i:i + 4]) or text.startswith("'\\u{", i):
            j = text.find("'", i + 1) + 1
            out.append(' ' * (j - i))
            i = j
        else:
            out.append(c)
            i += 1
    return ''.join(out)


def block_end(text, open_brace):
    """Index just past the `}` matching the `{` at `open_brace`."""
    depth = 0
    for j in range(open_brace, len(text)):
        if text[j] == '{':
            depth += 1
        elif text[j] == '}':
            depth -= 1
            if depth == 0:
                return j + 1
    return len(text)


CFG_TEST = re.compile(r'#\[cfg\(\s*test\s*\)\]')
MOD_DECL = re.compile(r'(?:pub(?:\([^)]*\))?\s+)?mod\s+(' + IDENT + r')\s*([;{])')


class Module:
    def __init__(self, path, file, text, line0):
        self.path = path          # tuple of names from the crate root
        self.file = file
        self.text = text          # code of this module only (children blanked)
        self.line0 = line0        # line number of text[0] in file
        self.children = {}
        self.reexports = {}       # name -> full path it points at
        self.items = set()        # names defined here


def blank(text, a, b):
    return text[:a] + re.sub(r'[^\n]', ' ', text[a:b]) + text[b:]


def drop_test_code(text):
    """Blanks every item under `#[cfg(test)]` (test modules, test-only functions)."""
    while True:
        m = CFG_TEST.search(text)
        if not m:
            return text
        j = m.end()
        # the item: up to its `;` or its `{ … }` block, whichever comes first
        semi = text.find(';', j)
        brace = text.find('{', j)
        if brace >= 0 and (semi < 0 or brace < semi):
            end = block_end(text, brace)
        else:
            end = semi + 1 if semi >= 0 else len(text)
        text = blank(text, m.start(), end)


def load_module(path, file, text, line0, mod_dir, modules):
    """Reads a module (file or inline) and its children; `mod_dir` holds its file children."""
    m = Module(path, file, text, line0)
    modules[path] = m
    pos = 0
    body = text
    while True:
        d = MOD_DECL.search(body, pos)
        if not d:
            break
        name, kind = d.group(1), d.group(2)
        if kind == ';':
            cands = [os.path.join(mod_dir, name + '.rs'), os.path.join(mod_dir, name, 'mod.rs')]
            found = next((c for c in cands if os.path.exists(c)), None)
            pos = d.end()
            if found:
                raw = open(found, encoding='utf-8').read()
                code = drop_test_code(strip_comments_and_strings(raw))
                child_dir = os.path.join(mod_dir, name)
                m.children[name] = load_module(path + (name,), found, code, 1, child_dir, modules)
        else:
            brace = d.end() - 1
            end = block_end(body, brace)
            inner = body[brace + 1:end - 1]
            line = line0 + body[:brace + 1].count('\n')
            m.children[name] = load_module(path + (name,), file, inner, line, os.path.join(mod_dir, name), modules)
            body = blank(body, brace + 1, end - 1)
            pos = end
    m.text = body
    for it in re.finditer(r'\b(?:fn|struct|enum|trait|type|const|static|union|macro_rules!)\s+(' + IDENT + ')', body):
        m.items.add(it.group(1))
    return m


def split_top(s):
    depth, cur, items = 0, '', []
    for ch in s:
        if ch == '{':
            depth += 1
        elif ch == '}':
            depth -= 1
        if ch == ',' and depth == 0:
            items.append(cur)
            cur = ''
        else:
            cur += ch
    items.append(cur)
    return [i.strip() for i in items if i.strip()]


def use_leaves(tree, prefix=()):
    tree = tree.strip()
    if tree.startswith('{'):
        out = []
        for it in split_top(tree[1:tree.rindex('}')]):
            out += use_leaves(it, prefix)
        return out
    m = re.match(r'(' + IDENT + r'|\*)\s*(?:::\s*(.*)|\s+as\s+(' + IDENT + r'))?$', tree, re.S)
    if not m:
        return []
    if m.group(2) is not None:
        return use_leaves(m.group(2), prefix + (m.group(1),))
    return [(prefix + (m.group(1),), m.group(3) or m.group(1))]


USE = re.compile(r'(?:pub(?:\([^)]*\))?\s+)?use\s+([^;]*);')


def resolve(modules, path):
    """The module a root-relative path's item is defined in, following re-exports."""
    if path is None:
        return None
    cur, rest = (), list(path)
    for _ in range(64):
        mod = modules.get(cur)
        if mod is None:
            return None
        if not rest or rest[0] == '*':
            return cur
        head = rest[0]
        if head in mod.children:
            cur, rest = cur + (head,), rest[1:]
            continue
        if head in mod.reexports and mod.reexports[head] != cur + (head,):
            target = mod.reexports[head]
            cur, rest = (), list(target) + rest[1:]
            continue
        return cur
    return cur


def check_crate(src_dir, lib):
    modules = {}
    raw = open(lib, encoding='utf-8').read()
    load_module((), lib, drop_test_code(strip_comments_and_strings(raw)), 1, src_dir, modules)
    # local names a module brings in with `use` (name -> absolute path), and re-exports
    local = {}
    for path, mod in modules.items():
        names = {}
        for u in USE.finditer(mod.text):
            for segs, alias in use_leaves(u.group(1)):
                if segs[0] in mod.children:
                    segs = ('self',) + segs
                if segs[0] in ('crate', 'self', 'super'):
                    absolute = absolute_path(path, segs)
                    if absolute is not None and segs[-1] != '*':
                        names[alias] = absolute
                        if u.group(0).lstrip().startswith('pub'):
                            mod.reexports[alias] = absolute
        local[path] = names
    edges = {}
    for path, mod in modules.items():
        out = edges.setdefault(path, {})

        def add(target, offset):
            if target is not None and target != path and target in modules:
                line = mod.line0 + mod.text[:offset].count('\n')
                out.setdefault(target, (mod.file, line))

        for u in USE.finditer(mod.text):
            if u.group(0).lstrip().startswith('pub'):
                continue
            for segs, _ in use_leaves(u.group(1)):
                if segs[0] in mod.children:
                    segs = ('self',) + segs
                if segs[0] in ('crate', 'self', 'super'):
                    add(resolve(modules, absolute_path(path, segs)), u.start())
        code = USE.sub(lambda m: re.sub(r'[^\n]', ' ', m.group(0)), mod.text)
        for p in re.finditer(r'(?<![A-Za-z0-9_:])((?:crate|self|super)(?:::' + IDENT + r')+)', code):
            segs = tuple(p.group(1).split('::'))
            add(resolve(modules, absolute_path(path, segs)), p.start())
        for p in re.finditer(r'(?<![A-Za-z0-9_:])(' + IDENT + r')((?:::' + IDENT + r')+)', code):
            head = p.group(1)
            if head in mod.children and head not in local[path]:
                add(resolve(modules, path + (head,) + tuple(p.group(2).split('::')[1:])), p.start())
            elif head in local[path]:
                add(resolve(modules, local[path][head] + tuple(p.group(2).split('::')[1:])), p.start())
    return modules, edges


def absolute_path(here, segs):
    """`crate::a::b` / `self::…` / `super::…` as a path from the crate root (names only)."""
    if segs[0] == 'crate':
        return tuple(segs[1:])
    if segs[0] == 'self':
        return here + tuple(segs[1:])
    cur, rest = here, list(segs)
    while rest and rest[0] == 'super':
        if not cur:
            return None
        cur, rest = cur[:-1], rest[1:]
    return cur + tuple(rest)


def circles(edges):
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges.get(root, {}))))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            advanced = False
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges.get(w, {})))))
                    advanced = True
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def cycle_in(comp, edges):
    """One cycle through the component's first module, as a list of modules."""
    members = set(comp)
    start = comp[0]
    prev, queue = {start: None}, [start]
    while queue:
        v = queue.pop(0)
        for w in sorted(edges.get(v, {})):
            if w == start:
                path = [v]
                while prev[path[-1]] is not None:
                    path.append(prev[path[-1]])
                return list(reversed(path)) + [start]
            if w in members and w not in prev:
                prev[w] = v
                queue.append(w)
    return comp


def name(crate, path):
    return crate + ('::' + '::'.join(path) if path else '')


def check(crate_dirs, out=sys.stdout):
    found = 0
    for d in crate_dirs:
        src = os.path.join(d, 'src')
        crate = os.path.basename(os.path.normpath(d))
        for root in ('lib.rs', 'main.rs'):
            lib = os.path.join(src, root)
            if not os.path.exists(lib):
                continue
            modules, edges = check_crate(src, lib)
            comps = circles(edges)
            print(f'{name(crate, ())} ({root}): {len(modules)} modules, '
                  f'{sum(len(e) for e in edges.values())} dependencies, {len(comps)} circles', file=out)
            nodes = {p for p, m in modules.items() if '#[node(' in m.text}
            for a in sorted(nodes):
                for b, (f, line) in sorted(edges[a].items()):
                    if b in nodes:
                        found += 1
                        print(f'  node module {name(crate, a)} uses node module {name(crate, b)}   '
                              f'({os.path.relpath(f)}:{line}): move what they share out of the node\'s file', file=out)
            for comp in comps:
                found += 1
                cyc = cycle_in(comp, edges)
                print(f'  circle of {len(comp)} modules: ' + ', '.join(name(crate, c) for c in comp), file=out)
                for a, b in zip(cyc, cyc[1:]):
                    f, line = edges[a][b]
                    print(f'    {name(crate, a)} -> {name(crate, b)}   ({os.path.relpath(f)}:{line})', file=out)
    return found


def workspace_members(root):
    text = open(os.path.join(root, 'Cargo.toml')).read()
    m = re.search(r'members\s*=\s*\[([^\]]*)\]', text)
    dirs = []
    for pat in re.findall(r'"([^"]+)"', m.group(1)):
        if pat.endswith('/*'):
            base = os.path.join(root, pat[:-2])
            dirs += sorted(os.path.join(base, e) for e in os.listdir(base) if os.path.isdir(os.path.join(base, e, 'src')))
        elif os.path.isdir(os.path.join(root, pat, 'src')):
            dirs.append(os.path.join(root, pat))
    return dirs


def self_test():
    """A crate with a circle through a re-export and a `super` path, and one without."""
    with tempfile.TemporaryDirectory() as tmp:
        def crate(name, files):
            for path, text in files.items():
                p = os.path.join(tmp, name, 'src', path)
                os.makedirs(os.path.dirname(p), exist_ok=True)
                open(p, 'w').write(text)
            return os.path.join(tmp, name)
        bad = crate('bad', {
            'lib.rs': 'pub mod a;\npub mod types;\n',
            'a.rs': 'use crate::types::Thing;\npub fn helper() {}\n',
            'types/mod.rs': 'mod thing;\npub use thing::Thing;\nfn g() { thing::make() }\n',
            'types/thing.rs': '// crate::a::nothing in a comment\npub struct Thing;\nfn f() { super::super::a::helper() }\n',
        })
        good = crate('good', {
            'lib.rs': 'pub mod a;\npub mod types;\n',
            'a.rs': 'use crate::types::Thing;\npub fn helper() {}\n',
            'types/mod.rs': 'mod thing;\npub use thing::Thing;\n',
            'types/thing.rs': 'pub struct Thing;\nconst S: &str = "crate::a::helper";\n'
                              '#[cfg(test)]\nmod tests {\n    use crate::a::helper;\n}\n',
        })
        import io
        log = io.StringIO()
        assert check([bad], log) == 1, log.getvalue()
        assert 'bad::a -> bad::types::thing' in log.getvalue() and 'bad::types::thing -> bad::a' in log.getvalue(), log.getvalue()
        assert '3 dependencies' in log.getvalue(), log.getvalue()
        log = io.StringIO()
        assert check([good], log) == 0, log.getvalue()
        nodes = crate('nodes', {
            'lib.rs': 'pub mod a;\npub mod b;\n',
            'a.rs': '#[node(category = "x")]\nimpl A {}\npub struct Shared;\n',
            'b.rs': 'use crate::a::Shared;\n#[node(category = "x")]\nimpl B {}\n',
        })
        log = io.StringIO()
        assert check([nodes], log) == 1 and 'node module nodes::b uses node module nodes::a' in log.getvalue(), log.getvalue()
    print('module_cycles.py self-test passed')


if __name__ == '__main__':
    if sys.argv[1:] == ['--self-test']:
        self_test()
        sys.exit(0)
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    dirs = sys.argv[1:] or workspace_members(root)
    n = check(dirs)
    print(f'{n} circles or node-to-node imports' if n else 'no circles between modules, no node module importing another')
    sys.exit(1 if n else 0)
