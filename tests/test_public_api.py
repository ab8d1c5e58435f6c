"""The public surface of the package and the layering of its sub-packages."""

import ast
import importlib
import pathlib
import types

import pytest

import torch_edgevf as ev

PACKAGE = pathlib.Path(ev.__file__).parent

# Every name of the package namespace: adding one is a decision, removing one breaks users.
PUBLIC = [
    "EdgeOperators",
    "EigenPairs",
    "FaceGeometry",
    "FieldData",
    "FieldDesigner",
    "GradientProjector",
    "MeshData",
    "MeshReport",
    "Singularities",
    "SparseSolver",
    "Topology",
    "Transporter",
    "aligned_field",
    "alignment_loss",
    "allocator",
    "angle_defects",
    "connection_laplacian",
    "constrained_field",
    "corner_angles",
    "cotan_laplacian",
    "covariant_derivative",
    "curl_div_operator",
    "curl_energy",
    "curl_free_field",
    "curl_loss",
    "curvature_aligned_field",
    "curvature_field",
    "data",
    "default_mesh",
    "design",
    "dihedral_angles",
    "div_energy",
    "div_free_field",
    "div_loss",
    "edge_lengths",
    "edge_vectors",
    "edges_from_vectors",
    "eigsh",
    "expm_multiply",
    "face_areas",
    "face_curl",
    "face_div",
    "face_geometry",
    "face_normals",
    "factorize",
    "fields",
    "geometry",
    "gradient",
    "heat_diffuse",
    "icosphere",
    "implicit_euler",
    "io",
    "laplace_beltrami",
    "learning",
    "linalg",
    "load_field",
    "load_mesh",
    "locate_singularities",
    "losses",
    "mass_matrix",
    "mesh",
    "meshes",
    "models",
    "module",
    "nn",
    "nth_power",
    "nth_root",
    "nth_roots",
    "operators",
    "param",
    "parametrize",
    "poisson",
    "project_on_gradients",
    "real_form",
    "remove_unreferenced_vertices",
    "render",
    "repair",
    "RepairReport",
    "RepairResult",
    "save_field",
    "save_mesh",
    "singularities",
    "smoothest_field",
    "smoothness_loss",
    "solve",
    "solve_constrained",
    "solve_fixed",
    "spectral_loss",
    "split_singular_faces",
    "topology",
    "transport",
    "transport_coefficients",
    "tune_allocator",
    "vertex_div_curl",
    "vertex_mass",
    "vertex_normals",
]


def test_public_surface_is_pinned():
    assert sorted(ev.__all__) == sorted(PUBLIC)
    assert len(set(ev.__all__)) == len(ev.__all__)
    for name in PUBLIC:
        assert hasattr(ev, name), name
    public_attributes = {n for n in dir(ev) if not n.startswith("_")}
    assert public_attributes == set(PUBLIC), public_attributes ^ set(PUBLIC)
    assert isinstance(ev.__version__, str)


def test_short_module_names_are_the_modules():
    assert ev.geometry is importlib.import_module("torch_edgevf.mesh.geometry")
    assert ev.topology is importlib.import_module("torch_edgevf.mesh.topology")
    assert ev.meshes is importlib.import_module("torch_edgevf.mesh.meshes")
    assert ev.module is importlib.import_module("torch_edgevf.operators.module")
    assert ev.design is importlib.import_module("torch_edgevf.fields.design")
    assert ev.param is importlib.import_module("torch_edgevf.fields.param")
    assert ev.poisson is importlib.import_module("torch_edgevf.fields.poisson")
    assert ev.data.PSBDataset is importlib.import_module("torch_edgevf.learning.datasets").PSBDataset
    assert ev.nn.LearnedDiffusion is importlib.import_module("torch_edgevf.learning.layers").LearnedDiffusion
    assert ev.models.EdgeFieldNet is importlib.import_module("torch_edgevf.learning.models").EdgeFieldNet
    assert ev.losses.spectral_loss is ev.spectral_loss


@pytest.mark.parametrize(
    "name", ["singularities", "transport", "design", "param", "poisson", "representation"]
)
def test_field_modules_are_not_shadowed(name):
    """``import torch_edgevf.fields.X as m`` gives the module, not a function of that name."""
    module = importlib.import_module(f"torch_edgevf.fields.{name}")
    assert isinstance(module, types.ModuleType)
    assert getattr(ev.fields, name) is module


@pytest.mark.parametrize("shim", ["data", "nn", "models", "losses", "fields", "operators", "linalg", "mesh"])
def test_every_exported_name_exists(shim):
    module = importlib.import_module(f"torch_edgevf.{shim}")
    for name in module.__all__:
        assert hasattr(module, name), f"torch_edgevf.{shim}.{name}"


# The layers, bottom up: a sub-package may import its own layer and those listed for it.
FOUNDATION = {"_dtypes", "_validation", "_version", "allocator"}
ALLOWED = {
    "mesh": FOUNDATION,
    "linalg": FOUNDATION,
    "operators": FOUNDATION | {"mesh", "linalg"},
    "fields": FOUNDATION | {"mesh", "linalg", "operators"},
    "learning": FOUNDATION | {"mesh", "linalg", "operators", "fields"},
}


def _imports(path: pathlib.Path):
    """(module path inside the package, imported names) of every relative import of a file."""
    tree = ast.parse(path.read_text())
    parts = path.relative_to(PACKAGE).with_suffix("").parts
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = list(parts[: len(parts) - node.level])
            target = base + (node.module.split(".") if node.module else [])
            yield target, [a.name for a in node.names]


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_layers_import_only_downwards(layer):
    bad = []
    for path in sorted((PACKAGE / layer).glob("*.py")):
        for target, names in _imports(path):
            if not target:  # "from .. import x": the package namespace
                bad.append(f"{path.name}: from the package __init__ {names}")
                continue
            top = target[0]
            if top != layer and top not in ALLOWED[layer]:
                bad.append(f"{path.name}: {'.'.join(target)}")
    assert not bad, bad


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_no_private_name_crosses_a_sub_package(layer):
    bad = []
    for path in sorted((PACKAGE / layer).glob("*.py")):
        for target, names in _imports(path):
            if target and target[0] != layer and target[0] not in FOUNDATION:
                bad += [f"{path.name}: {'.'.join(target)}.{n}" for n in names if n.startswith("_")]
                bad += [f"{path.name}: {'.'.join(target)}" for part in target[1:] if part.startswith("_")]
    assert not bad, bad
