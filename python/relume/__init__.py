"""relume from Python: node graphs for global-illumination research.

Load a graph file, set parameters with the command line's checks, run it through the same
engine and disk cache as ``relume run``, and get its images as numpy arrays::

    import relume
    g = relume.Graph.load("graphs/filters.ron")
    g.set("blur.sigma", 1.5)            # or g["blur"]["sigma"] = 1.5
    r = g.run()
    r.images["image"]                    # float32, height x width x 3, linear RGB
    r.metrics["metrics"]["rel_mse"]      # the graph's error figures
    r.ran                                # the nodes the edit re-ran

``relume.nodes()`` is the catalogue of node kinds, with each parameter's schema. A numpy
array feeds an image input with ``g.feed("blur.image", array)``; ``@relume.node`` makes a
Python function a node kind (see ``relume.node``).
"""

from ._relume import GraphError, RunError, RunResult, nodes, read_image, write_image
from ._relume import Graph as _NativeGraph
from ._nodes import Image, Metrics, node, param

__all__ = [
    "Graph",
    "Node",
    "GraphError",
    "RunError",
    "RunResult",
    "nodes",
    "read_image",
    "write_image",
    "node",
    "param",
    "Image",
    "Metrics",
]


class Node:
    """One node's parameters: ``node["kd"]`` reads a value, ``node["kd"] = v`` sets it with
    the checks of ``relume run --set`` (``GraphError`` on a bad name or value)."""

    def __init__(self, graph, node_id):
        self._graph = graph
        self.id = node_id

    def __getitem__(self, param):
        return self._graph.get(f"{self.id}.{param}")

    def __setitem__(self, param, value):
        self._graph.set(f"{self.id}.{param}", value)

    @property
    def kind(self):
        """The node's kind, e.g. ``"GaussianBlur"``."""
        return next(n["kind"] for n in self._graph.nodes if n["id"] == self.id)

    @property
    def doc(self):
        """The kind's documentation (the node's doc comment, as the editor's tooltip shows it)."""
        kind = self.kind
        return next(n["doc"] for n in nodes() if n["kind"] == kind)

    @property
    def params(self):
        """The kind's parameter schemas (name, type, default, range, unit, help) with each
        parameter's value in this graph under ``value``."""
        kind = self.kind
        schema = next(n["params"] for n in nodes() if n["kind"] == kind)
        return [dict(p, value=self[p["name"]]) for p in schema]

    def __repr__(self):
        return f"<relume.Node {self.id}: {self.kind}>"


class Graph(_NativeGraph):
    """A node graph read from a ``.ron`` file and the engine that runs it.

    ``cache=`` names the disk-cache folder (default: ``$RELUME_CACHE``, else ``.relume-cache``
    in the current folder, as the command line); ``no_disk_cache=True`` keeps results in
    memory only. The engine is kept between runs: after an edit, ``run()`` re-runs only what
    the edit reaches.
    """

    @classmethod
    def load(cls, path, *, cache=None, no_disk_cache=False):
        """Reads and validates a graph file (``GraphError`` with file, line and column)."""
        return cls(path, cache=cache, no_disk_cache=no_disk_cache)

    def __getitem__(self, node_id):
        if not any(n["id"] == node_id for n in self.nodes):
            raise KeyError(f'no node "{node_id}" in the graph')
        return Node(self, node_id)

    def __setitem__(self, assignment, value):
        self.set(assignment, value)

    def run(self, outputs=None, *, progress="auto"):
        """Runs the graph and returns a ``RunResult``.

        ``outputs``: the output names to compute (default: all). ``progress``: a callable
        ``progress(node, fraction)``, ``True`` for a progress bar (tqdm's, in a terminal or a
        notebook), ``False`` for none, or ``"auto"``: a bar when tqdm is installed, shown only
        for a run that lasts more than a second. Ctrl-C cancels the run and raises
        ``KeyboardInterrupt``.
        """
        if callable(progress):
            return super().run(outputs, progress=progress)
        bar = _bar(delay=1.0 if progress == "auto" else 0.0) if progress else None
        if bar is None:
            return super().run(outputs)
        try:
            return super().run(outputs, progress=bar.update_node)
        finally:
            bar.close()


class _Bar:
    """A tqdm bar counting the nodes that finished, with the running node's share."""

    def __init__(self, tqdm, delay):
        self._bar = tqdm(total=None, unit="node", desc="relume", delay=delay, leave=False)
        self._done = set()

    def update_node(self, node, fraction):
        if fraction >= 1.0 and node not in self._done:
            self._done.add(node)
            self._bar.update(1)
        self._bar.set_postfix_str(f"{node} {fraction:.0%}", refresh=False)

    def close(self):
        self._bar.close()


def _bar(delay):
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return _Bar(tqdm, delay)
