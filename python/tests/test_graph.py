"""Loading, parameters, runs and outputs, against what the command line does with the same
graph and parameters."""

import numpy as np
import pytest

import relume
from conftest import GRAPHS, cli


def test_the_catalogue_has_every_kind_with_its_schema():
    kinds = {n["kind"]: n for n in relume.nodes()}
    blur = kinds["GaussianBlur"]
    assert "Gaussian" in blur["doc"]
    assert [p["name"] for p in blur["inputs"]] == ["image"] and blur["outputs"][0]["type"] == "Image"
    sigma = next(p for p in blur["params"] if p["name"] == "sigma")
    assert sigma["type"] == "float" and sigma["range"][0] >= 0 and isinstance(sigma["default"], float)
    tonemap = next(p for p in kinds["Tonemap"]["params"] if p["name"] == "operator")
    assert "Reinhard" in tonemap["choices"]
    assert len(kinds) > 60


def test_a_graph_loads_with_its_nodes_outputs_and_values(filters):
    g = relume.Graph.load(filters, no_disk_cache=True)
    assert [n["id"] for n in g.nodes][:3] == ["clean", "noisy", "sum"]
    assert g.outputs == ["image", "metrics"]
    assert g.get("blur.sigma") == 0.8
    assert g["tonemap"]["operator"] == "Reinhard"
    assert g.get("clean.color") == (0.9, 0.5, 0.2)
    g["blur"]["sigma"] = 1.25
    assert g.get("blur.sigma") == 1.25
    g.set("tonemap.operator", "Aces")
    assert "operator: Aces" in g.to_ron()


@pytest.mark.parametrize(
    "assignment, value, cli_value",
    [
        ("blurr.sigma", 1.0, "1.0"),  # unknown node
        ("blur.sigmaa", 1.0, "1.0"),  # unknown parameter: "did you mean"
        ("blur.sigma", -3.0, "-3.0"),  # out of range
        ("blur.sigma", "wide", "wide"),  # wrong type
        ("tonemap.operator", "Reinhardt", "Reinhardt"),  # not a variant
        ("clean.color", (1.0, 2.0), "(1.0, 2.0)"),  # wrong length
        ("blur", 1.0, "1.0"),  # not node.param
    ],
)
def test_every_set_error_is_a_graph_error_with_the_command_lines_message(filters, relume_bin, tmp_path, assignment, value, cli_value):
    g = relume.Graph.load(filters, no_disk_cache=True)
    with pytest.raises(relume.GraphError) as e:
        g.set(assignment, value)
    assert isinstance(e.value, ValueError)
    run = cli(relume_bin, "run", filters, "--set", f"{assignment}={cli_value}", "--no-disk-cache", "--out", tmp_path / "o", "-q")
    assert run.returncode != 0
    assert str(e.value) in run.stderr, (str(e.value), run.stderr)
    if "." in assignment and not assignment.startswith("blurr"):
        assert e.value.node == assignment.split(".")[0]


def test_a_graph_file_error_carries_file_line_and_column(tmp_path):
    bad = tmp_path / "bad.ron"
    bad.write_text((GRAPHS / "filters.ron").read_text().replace('"blur": (kind: "GaussianBlur"', '"blur": (kind: "GaussianBlurr"'))
    with pytest.raises(relume.GraphError) as e:
        relume.Graph.load(bad)
    assert e.value.file == str(bad) and e.value.line is not None and e.value.column is not None
    assert "GaussianBlur" in str(e.value), "the closest kind is named"


def test_the_image_is_float32_and_equals_the_exr_the_command_line_writes_bit_for_bit(filters, relume_bin, tmp_path):
    g = relume.Graph.load(filters, no_disk_cache=True)
    g.set("blur.sigma", 1.5)
    r = g.run()
    img = r.images["image"]
    assert img.dtype == np.float32 and img.shape == (64, 96, 3)
    assert r["image"] is img
    out = tmp_path / "cli"
    run = cli(relume_bin, "run", filters, "--set", "blur.sigma=1.5", "--no-disk-cache", "--out", out, "-q")
    assert run.returncode == 0, run.stderr
    exr = relume.read_image(out / "image.exr")
    assert exr.tobytes() == img.tobytes()
    assert set(r.metrics["metrics"]) >= {"rel_mse"} and all(isinstance(v, float) for v in r.metrics["metrics"].values())
    assert r.report["outputs"] == ["image", "metrics"] and r.report["ran"] == 7


def test_an_edit_re_runs_only_what_it_reaches(filters):
    g = relume.Graph.load(filters, no_disk_cache=True)
    first = g.run()
    assert sorted(first.ran) == ["blur", "clean", "error", "median", "noisy", "sum", "tonemap"]
    g["blur"]["sigma"] = 2.0
    second = g.run()
    assert sorted(second.ran) == ["blur", "error", "tonemap"]
    assert not np.array_equal(first.images["image"], second.images["image"])
    g["tonemap"]["exposure"] = 1.0
    assert g.run(["image"]).ran == ["tonemap"]


def test_the_disk_cache_is_shared_with_the_command_line(filters, relume_bin, tmp_path):
    cache = tmp_path / "cache"
    run = cli(relume_bin, "run", filters, "--cache", cache, "--cache-all", "--out", tmp_path / "o", "-q")
    assert run.returncode == 0, run.stderr
    r = relume.Graph.load(filters, cache=cache).run()
    assert r.ran == [] and {n["cache"] for n in r.report["nodes"]} == {"disk"}


def test_a_progress_callback_hears_every_node_finish(filters):
    heard = {}
    relume.Graph.load(filters, no_disk_cache=True).run(progress=lambda node, f: heard.__setitem__(node, f))
    assert set(heard) == {"blur", "clean", "error", "median", "noisy", "sum", "tonemap"}
    assert all(f == 1.0 for f in heard.values())


def test_images_round_trip_through_exr_exactly_and_png_within_a_step(tmp_path):
    rng = np.random.default_rng(3)
    img = rng.random((5, 7, 3), dtype=np.float32)
    relume.write_image(tmp_path / "a.exr", img)
    assert relume.read_image(tmp_path / "a.exr").tobytes() == img.tobytes()
    relume.write_image(tmp_path / "a.png", img)
    assert np.abs(relume.read_image(tmp_path / "a.png") - img).max() < 0.02
    grey = relume.read_image(tmp_path / "a.exr")[..., 0]
    relume.write_image(tmp_path / "g.exr", grey)
    assert relume.read_image(tmp_path / "g.exr").shape == (5, 7, 3)
    with pytest.raises(ValueError):
        relume.write_image(tmp_path / "b.exr", np.zeros((2, 2, 2)))
    with pytest.raises(OSError):
        relume.read_image(tmp_path / "missing.exr")


def test_a_graph_shrinks_to_the_size_the_tests_run_it_at():
    g = relume.Graph.load(GRAPHS / "reference_cornell.ron", no_disk_cache=True)
    assert g.get("truth.spp") == 4096
    g.shrink_to_test_size()
    schema = {n["kind"]: {p["name"]: p for p in n["params"]} for n in relume.nodes()}
    assert g.get("truth.spp") == schema["PathTrace"]["spp"]["test"] < 4096
    assert g.get("scene.width") == schema["LoadScene"]["width"]["test"] > 0


def test_a_graph_built_in_python_is_saved_and_the_command_line_runs_it_to_the_same_bytes(relume_bin, tmp_path):
    g = relume.Graph(no_disk_cache=True)
    pattern = g.add("TestPattern", width=40, height=30, pattern="Checker", noise=0.2, seed=3)
    assert pattern == "test_pattern"
    assert g.add("GaussianBlur", id="blur", sigma=1.5) == "blur"
    g.connect("test_pattern.image", "blur.image")
    g.output("image", "blur.image")
    with pytest.raises(relume.GraphError, match="already"):
        g.add("GaussianBlur", id="blur")
    with pytest.raises(relume.GraphError, match='did you mean "GaussianBlur"'):
        g.add("GausianBlur")
    with pytest.raises(relume.GraphError, match="out of range"):
        g.add("GaussianBlur", id="wide", sigma=-1.0)
    assert "wide" not in [n["id"] for n in g.nodes], "a refused node is not left behind"
    with pytest.raises(relume.GraphError):
        g.connect("blur.image", "test_pattern.image")  # TestPattern has no image input
    img = g.run().images["image"]
    assert img.shape == (30, 40, 3)
    path = tmp_path / "built.ron"
    g.save(path)
    out = tmp_path / "out"
    run = cli(relume_bin, "run", path, "--no-disk-cache", "--out", out, "-q")
    assert run.returncode == 0, run.stderr
    assert relume.read_image(out / "image.exr").tobytes() == img.tobytes()
    assert relume.Graph.load(path, no_disk_cache=True).to_ron() == g.to_ron()


def test_a_node_shows_its_kind_doc_and_parameters_with_their_values(filters):
    g = relume.Graph.load(filters, no_disk_cache=True)
    blur = g["blur"]
    assert blur.kind == "GaussianBlur"
    catalogue = {n["kind"]: n for n in relume.nodes()}
    assert blur.doc == catalogue["GaussianBlur"]["doc"] and "Gaussian" in blur.doc
    sigma = next(p for p in blur.params if p["name"] == "sigma")
    assert sigma["value"] == g.get("blur.sigma") and sigma["type"] == "float"
