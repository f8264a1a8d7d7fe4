"""Nodes written in Python: ``@relume.node`` turns a function into a node kind.

Arguments without a default are the node's input ports, those with one its parameters; the
annotations give the port types (``relume.Image``: a float32 array, height x width x 3;
``relume.Metrics``: a dict of floats, or one float), the return annotation (or ``outputs=``)
the outputs. The cache key of a run holds a hash of the function's source, its parameters and
its inputs, so editing the function, a parameter or an upstream node re-runs it and nothing
else does. What the function reads from outside its arguments (a global, a helper's body) is
not in the key. Such kinds exist only in the Python process that defined them.
"""

import inspect
import marshal
from typing import Any

from ._relume import _define_node


class Image:
    """Port type of a Python node: an image, a float32 numpy array (height x width x 3,
    linear RGB). A returned array may also be height x width x 4 or height x width."""


class Metrics:
    """Port type of a Python node: named figures, a dict of str to float (a returned single
    number is named after its port)."""


def param(default, *, min=None, max=None, unit="", help="") -> Any:
    """A Python node parameter's default with its range, unit and help::

        def gain(image: relume.Image, k: float = relume.param(1.0, min=0.0, max=8.0)) -> relume.Image:

    (Typed ``Any`` so that it stands as the default of a ``float`` or ``int`` argument.)
    """
    return _Param(default, min=min, max=max, unit=unit, help=help)


class _Param:
    def __init__(self, default, *, min=None, max=None, unit="", help=""):
        if (min is None) != (max is None):
            raise ValueError("a range takes both min and max")
        self.default = default
        self.range = None if min is None else (float(min), float(max))
        self.unit = unit
        self.help = help

    def __repr__(self):
        return f"relume.param({self.default!r}, range={self.range})"


def _type_name(annotation, where):
    if annotation is inspect.Parameter.empty or annotation is inspect.Signature.empty:
        return "Image"
    name = annotation if isinstance(annotation, str) else getattr(annotation, "__name__", repr(annotation))
    name = name.rsplit(".", 1)[-1]
    if name not in ("Image", "Metrics"):
        raise TypeError(f"{where}: a Python node's ports are relume.Image or relume.Metrics, not {name}")
    return name


def _camel(name):
    return "".join(part[:1].upper() + part[1:] for part in name.split("_") if part)


def _source(func):
    try:
        return inspect.getsource(func)
    except (OSError, TypeError):
        # Defined where no file holds its text (a REPL line, exec): its code object, which
        # changes when the function does.
        return marshal.dumps(func.__code__).hex()


def node(func=None, *, kind=None, outputs=None):
    """Makes ``func`` a node kind (named ``kind``, else the function's name in CamelCase)
    that graphs built or loaded in this process can use: ``g.add("Gain", k=2.0)``.

    ``outputs``: a dict of output name to ``relume.Image`` or ``relume.Metrics``; by default
    one output, ``image`` or ``metrics`` after the return annotation. With several outputs the
    function returns a tuple in that order or a dict by name. The docstring is the node's doc.
    Defining a kind again (a notebook cell run twice) replaces it; runs after that use the new
    function, and its results are new cache entries.
    """

    def define(f):
        try:
            sig = inspect.signature(f, eval_str=True)
        except TypeError:  # Python 3.9: no eval_str; string annotations are read by name
            sig = inspect.signature(f)
        inputs, params = [], []
        for p in sig.parameters.values():
            if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
                raise TypeError(f"{f.__name__}: a Python node takes named arguments only, not *{p.name}")
            if p.default is p.empty:
                inputs.append((p.name, _type_name(p.annotation, f"input {p.name}")))
            elif isinstance(p.default, _Param):
                d = p.default
                params.append((p.name, d.default, d.range, d.unit, d.help))
            else:
                params.append((p.name, p.default, None, "", ""))
        if outputs is None:
            ty = _type_name(sig.return_annotation, "the return annotation")
            outs = [(ty.lower(), ty)]
        else:
            outs = [(name, _type_name(t, f"output {name}")) for name, t in outputs.items()]
        name = kind or _camel(f.__name__)
        _define_node(name, inspect.getdoc(f) or "", inputs, outs, params, _source(f), f)
        f.kind = name
        return f

    return define(func) if func is not None else define
