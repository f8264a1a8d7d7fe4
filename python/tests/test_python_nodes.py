"""Nodes written in Python and arrays fed from numpy: cached and re-run like compiled nodes."""

import numpy as np
import pytest

import relume

from conftest import cli


def pattern_graph():
    g = relume.Graph(no_disk_cache=True)
    g.add("TestPattern", id="pattern", width=24, height=16, pattern="Checker", noise=0.1, seed=5)
    return g


def test_a_python_node_is_cached_and_re_run_by_its_parameters_and_its_source():
    calls = []

    @relume.node
    def py_gain(image: relume.Image, k: float = relume.param(1.0, min=0.0, max=8.0)) -> relume.Image:
        """Scales an image by k."""
        calls.append(k)
        return image * k

    assert py_gain.kind == "PyGain"
    g = pattern_graph()
    g.add("PyGain", id="gain", k=2.0)
    g.connect("pattern.image", "gain.image")
    g.output("image", "gain.image")
    g.output("plain", "pattern.image")
    first = g.run()
    assert set(first.ran) == {"pattern", "gain"}
    np.testing.assert_array_equal(first["image"], first["plain"] * np.float32(2.0))
    assert g.run().ran == [], "nothing changed: everything from the cache"
    g["gain"]["k"] = 3.0
    third = g.run()
    assert third.ran == ["gain"], "a parameter edit re-runs the Python node only"
    np.testing.assert_array_equal(third["image"], first["plain"] * np.float32(3.0))
    with pytest.raises(relume.GraphError, match="out of range"):
        g["gain"]["k"] = 9.0
    assert calls == [2.0, 3.0]

    @relume.node(kind="PyGain")
    def py_gain_again(image: relume.Image, k: float = relume.param(1.0, min=0.0, max=8.0)) -> relume.Image:
        return image * k + 1.0

    again = g.run()
    assert again.ran == ["gain"], "a new definition re-runs its nodes"
    np.testing.assert_array_equal(again["image"], first["plain"] * np.float32(3.0) + np.float32(1.0))
    schema = {n["kind"]: n for n in relume.nodes()}["PyGain"]
    assert schema["category"] == "python"
    assert [(p["name"], p["range"]) for p in schema["params"]] == [("k", (0.0, 8.0))]


def test_a_python_error_metric_takes_two_images_and_gives_figures():
    @relume.node(outputs={"metrics": relume.Metrics, "diff": relume.Image})
    def py_abs_error(image, reference, scale: int = 1):
        d = np.abs(image - reference) * scale
        return {"metrics": {"mae": float(d.mean()), "max": float(d.max())}, "diff": d}

    g = pattern_graph()
    g.add("GaussianBlur", id="blur", sigma=1.0)
    g.connect("pattern.image", "blur.image")
    g.add("PyAbsError", id="err")
    g.connect("blur.image", "err.image")
    g.connect("pattern.image", "err.reference")
    g.output("metrics", "err.metrics")
    g.output("diff", "err.diff")
    g.output("blur", "blur.image")
    g.output("plain", "pattern.image")
    r = g.run()
    want = np.abs(r["blur"] - r["plain"])
    assert r.metrics["metrics"]["mae"] == pytest.approx(float(want.mean()), rel=1e-6)
    assert r.metrics["metrics"]["max"] == pytest.approx(float(want.max()), rel=1e-6)
    np.testing.assert_array_equal(r.images["diff"], want)
    g["blur"]["sigma"] = 2.0
    assert g.run().ran == ["blur", "err"]


def test_a_python_node_that_raises_fails_the_run_with_its_exception():
    @relume.node
    def py_broken(image: relume.Image) -> relume.Image:
        raise ValueError("the filter does not converge")

    g = pattern_graph()
    g.add("PyBroken", id="broken")
    g.connect("pattern.image", "broken.image")
    g.output("image", "broken.image")
    with pytest.raises(relume.RunError, match="ValueError: the filter does not converge"):
        g.run()


def test_python_node_definitions_are_checked():
    with pytest.raises(ValueError, match="built-in"):
        relume.node(kind="GaussianBlur")(lambda image: image)
    with pytest.raises(TypeError, match="relume.Image or relume.Metrics"):

        @relume.node
        def py_bad_port(image: int) -> relume.Image:
            return image

    with pytest.raises(ValueError, match="bool, an int, a float or a str"):

        @relume.node
        def py_bad_param(image, k=[1, 2]) -> relume.Image:
            return image

    with pytest.raises(ValueError, match="range"):

        @relume.node
        def py_bad_default(image, k=relume.param(9.0, min=0.0, max=1.0)) -> relume.Image:
            return image


def test_a_fed_array_runs_like_the_same_pixels_loaded_from_a_file(tmp_path):
    rng = np.random.default_rng(7)
    array = rng.random((12, 20, 3), dtype=np.float32)
    relume.write_image(tmp_path / "a.exr", array)
    loaded = relume.Graph(no_disk_cache=True)
    loaded.add("LoadImage", id="load", path=str(tmp_path / "a.exr"))
    loaded.add("GaussianBlur", id="blur", sigma=1.2)
    loaded.connect("load.image", "blur.image")
    loaded.output("image", "blur.image")

    fed = relume.Graph(no_disk_cache=True)
    fed.add("GaussianBlur", id="blur", sigma=1.2)
    fed.output("image", "blur.image")
    assert fed.feed("blur.image", array) == "blur_image_array"
    r = fed.run()
    assert set(r.ran) == {"blur_image_array", "blur"}
    assert r["image"].tobytes() == loaded.run()["image"].tobytes()
    fed.feed("blur.image", array.copy())
    assert fed.run().ran == [], "the same pixels again: nothing re-runs"
    fed.feed("blur.image", array[..., 0])  # grey: one channel repeated
    grey = fed.run()
    assert set(grey.ran) == {"blur_image_array", "blur"}
    assert not np.array_equal(grey["image"], r["image"])
    with pytest.raises(ValueError, match="height × width × 3"):
        fed.feed("blur.image", np.zeros((2, 2, 2)))
    with pytest.raises(relume.GraphError):
        fed.feed("nowhere.image", array)


def test_a_graph_with_a_python_node_is_refused_by_the_command_line_by_name(relume_bin, tmp_path):
    @relume.node
    def py_invert(image: relume.Image) -> relume.Image:
        return 1.0 - image

    g = pattern_graph()
    g.add("PyInvert", id="invert")
    g.connect("pattern.image", "invert.image")
    g.output("image", "invert.image")
    path = tmp_path / "python_node.ron"
    g.save(path)
    assert relume.Graph.load(path, no_disk_cache=True).run()["image"].shape == (16, 24, 3)
    run = cli(relume_bin, "check", path)
    assert run.returncode != 0
    assert "PyInvert" in run.stderr
