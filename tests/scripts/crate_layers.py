#!/usr/bin/env python3
"""Checks the workspace's crate graph against its layers, and prints it.

The layers, from the ground up (docs/ARCHITECTURE.md draws them):
  relume-macros, relume-core       the node-graph engine; no rendering
  relume-build                     a build-script helper: each node crate's registration
  relume-base                      math, BRDFs, shared port types, render library, shared nodes
  relume-pbgi, relume-relight,     one crate per pipeline family: each depends on core and base
  relume-ptt, relume-volume        only, never on another pipeline
  relume-cli, relume-editor,       the applications: they alone may depend on pipeline crates
  relume-python, relume-tests,
  relume-benches
Dev-dependencies count as dependencies, with one exception: relume-macros' crate doc example
declares and runs a node through relume-core (which re-exports the macros), so relume-macros
may dev-depend on relume-core.
Only relume-cli may depend on clap, timely, plotters or ctrlc (the command line's libraries);
egui and eframe only in relume-editor; pyo3 and numpy only in relume-python.

usage: crate_layers.py            (reads `cargo metadata`; exit 1 on a violation)
"""
import json
import subprocess
import sys

PIPELINES = {'relume-pbgi', 'relume-relight', 'relume-ptt', 'relume-volume'}
APPS = {'relume-cli', 'relume-editor', 'relume-python', 'relume-tests', 'relume-benches'}
ALLOWED = {
    'relume-macros': set(),
    'relume-build': set(),
    'relume-core': {'relume-macros'},
    'relume-base': {'relume-core'},
    **{p: {'relume-core', 'relume-base'} for p in PIPELINES},
}
# Dev-dependencies a crate's doc examples need beyond its layer (see the docstring).
DOC_EXAMPLES = {'relume-macros': {'relume-core'}}
CLI_ONLY = {'clap', 'timely', 'plotters', 'ctrlc'}
EDITOR_ONLY = {'egui', 'eframe', 'egui_node_graph2'}
PYTHON_ONLY = {'pyo3', 'numpy'}


def main():
    meta = json.loads(subprocess.run(['cargo', 'metadata', '--format-version', '1', '--no-deps'],
                                     capture_output=True, text=True, check=True).stdout)
    members = {p['name']: p for p in meta['packages']}
    problems = []
    print('crate graph (relume crates; dev-dependencies in brackets):')
    for name in sorted(members):
        deps = members[name]['dependencies']
        own = sorted({d['name'] for d in deps if d['name'] in members and d.get('kind') is None})
        dev = sorted({d['name'] for d in deps if d['name'] in members and d.get('kind') == 'dev'} - set(own))
        print(f'  {name} -> {", ".join(own) or "-"}' + (f' [{", ".join(dev)}]' if dev else ''))
        relume = set(own) | (set(dev) - DOC_EXAMPLES.get(name, set()))
        if name in ALLOWED and not relume <= ALLOWED[name]:
            problems.append(f'{name} depends on {", ".join(sorted(relume - ALLOWED[name]))}: its layer allows only '
                            f'{", ".join(sorted(ALLOWED[name])) or "no relume crate"}')
        if name not in ALLOWED and name not in APPS:
            problems.append(f'{name} is in no layer: add it to tests/scripts/crate_layers.py and docs/ARCHITECTURE.md')
        external = {d['name'] for d in deps if d.get('kind') is None}
        if name != 'relume-cli' and external & CLI_ONLY:
            problems.append(f'{name} depends on {", ".join(sorted(external & CLI_ONLY))}, which only relume-cli may use')
        if name != 'relume-editor' and external & EDITOR_ONLY:
            problems.append(f'{name} depends on {", ".join(sorted(external & EDITOR_ONLY))}, which only relume-editor may use')
        if name != 'relume-python' and external & PYTHON_ONLY:
            problems.append(f'{name} depends on {", ".join(sorted(external & PYTHON_ONLY))}, which only relume-python may use')
    for p in problems:
        print('layer violation: ' + p, file=sys.stderr)
    print('the crates keep their layers' if not problems else f'{len(problems)} layer violations')
    sys.exit(1 if problems else 0)


if __name__ == '__main__':
    main()
