"""experiments/psb_classification: the README's and the report's tables, p-values and verdicts are those of
the saved runs."""

import collections
import json
import statistics

import numpy as np
import pytest

from study import STUDY, euler_of_closed, paired_rows, run

#: the study's README: its tables, its reading and its report
README = "experiments/psb_classification/README.md"


@pytest.fixture(scope="module")
def bench():
    """The study's command, ``experiments/psb_classification/run.py``."""
    return run


#: this release's runs of the recommended recipe, the reference of the README's verdicts
RERUN = "edgefieldnet, 4 stretched copies, coefficients, averaged last 10"
ROOT = STUDY.parents[1]


_ALIKE = "diffusionnet-nodropout, 4 stretched copies, averaged last 10"
#: the recommended network, with the recommended recipe
_NEW = "edgefieldnet-nodiv-meanpool, 4 stretched copies, averaged last 10"
_DROPOUT_ALIKE = "diffusionnet, 4 stretched copies, averaged last 10"
_ABLATIONS = [
    f"edgefieldnet-{a}, 4 stretched copies, averaged last 10" for a in ("scalar", "vertexvec", "fixedtime")
]
#: both networks with the mean curvature signature after the HKS (``--input hks+curvature``)
_CURVATURE = [
    f"{m}, mean curvature input, 4 stretched copies, coefficients, averaged last 10"
    for m in ("edgefieldnet", "diffusionnet-nodropout")
]
#: (reference, partitions, phrase, rows): the phrase with the rows' p-values against the
#: reference (the earlier runs where it is empty) on the folds of those partitions (None:
#: all), as the table prints them
README_P_VALUES = [
    (RERUN, (0,), "p = {} against the faithful DiffusionNet's own recipe", ["diffusionnet-nodropout"]),
    (
        RERUN,
        (0,),
        "{} against it trained alike and {} against DiffusionNet with dropout",
        [_ALIKE, _DROPOUT_ALIKE],
    ),
    (RERUN, (0,), "the same tests give p = {}, {} and {}", _ABLATIONS),
    ("", (0,), "(the earlier runs: {}, {} and {};", ["diffusionnet-nodropout", _ALIKE, _DROPOUT_ALIKE]),
    ("", (0,), "vertex gradients p = {}", [_ABLATIONS[1]]),
    ("", (0,), "times not learned p = {}", [_ABLATIONS[2]]),
    ("", (0,), "vector stream p = {}", [_ABLATIONS[0]]),
    (RERUN, None, "p = {} against the first and {} against the second", ["diffusionnet-nodropout", _ALIKE]),
    (RERUN, None, "with a second partition of the folds, p = {} over both", ["diffusionnet-nodropout"]),
    (RERUN, None, "run on it) the three losses are significant: p = {}, {} and {}", _ABLATIONS),
    (RERUN, (0,), "neither lead is significant (p = {} and {} by", ["diffusionnet-nodropout", _ALIKE]),
    (_CURVATURE[1], (0,), "the gain is DiffusionNet's (p = {} against it trained alike", [_ALIKE]),
    (_CURVATURE[0], (0,), "the edge-field network's is none (p = {})", [RERUN]),
    (_CURVATURE[1], (0,), "edge-field network on the HKS alone (1,086 against 1,085, p = {})", [RERUN]),
    (
        RERUN.removesuffix(", averaged last 10"),
        None,
        "their losses are not significant (p = {} and {}",
        [a.removesuffix(", averaged last 10") for a in _ABLATIONS[1:]],
    ),
]


#: the README's short verdicts: (phrase, rows), each row (label, split, partition) and
#: the phrase filled with the accuracy of its runs on seeds 0-2, over every fold for "folds"
README_SUMMARY = [
    (
        "classifies **{}** of the file's fixed split (76 test meshes, 3 seeds; the target 0.90; {} with "
        "the final weights, and one seed moves by 2-4 meshes) and **{}** over 5 folds on 3 seeds (1,140 "
        "test meshes), where the faithful DiffusionNet classifies {} with its own recipe and {} trained "
        "alike",
        [
            (_NEW, "fixed"),
            (_NEW.removesuffix(", averaged last 10"), "fixed"),
            (_NEW, "folds"),
            ("diffusionnet-nodropout", "folds"),
            (_ALIKE, "folds"),
        ],
    ),
    (
        "`EdgeFieldNet` classifies **{}**, the faithful DiffusionNet {} with its own recipe and {} "
        "trained alike",
        [(RERUN, "folds"), ("diffusionnet-nodropout", "folds"), (_ALIKE, "folds")],
    ),
    (
        "vector stream the same network classifies {} of those meshes; with DiffusionNet's vertex "
        "gradients in place of the edge operators {}, and with the diffusion times frozen {}.",
        [(a, "folds") for a in _ABLATIONS],
    ),
    (
        "(76 test meshes, 3 seeds): {}, short of the 0.90 target.** DiffusionNet classifies {} with its own "
        "recipe and {} trained alike, and {} given the mean curvature as extra input.",
        [(RERUN, "fixed"), ("diffusionnet-nodropout", "fixed"), (_ALIKE, "fixed"), (_CURVATURE[1], "fixed")],
    ),
]


#: the README's recipes, and what they add to the :func:`label` of a run
README_RECIPES = {
    "DiffusionNet's": "",
    "stretched copies up to 1.25, averaged weights": ", 4 stretched copies, averaged last 10",
    "stretched copies up to 1.5, averaged weights": ", 4 stretched copies (up to 1.5), averaged last 10",
    "stretched copies up to 1.25, averaged weights; this release's code": (
        ", 4 stretched copies, coefficients, averaged last 10"
    ),
}
#: the README's learning rows, (model, recipe: "copies" for either recipe with copies), and
#: the :func:`label` of their runs
README_ROWS = {
    (
        '`EdgeFieldNet(log_features=True, divergence=False, pool="mean")`',
        "copies",
    ): "edgefieldnet-nodiv-meanpool",
    ("`EdgeFieldNet(log_features=True)`", "copies"): "edgefieldnet",
    ("DiffusionNet with dropout 0.5", "copies"): "diffusionnet",
    ("DiffusionNet with dropout 0.5", "DiffusionNet's"): "diffusionnet",
    ("DiffusionNet, as its public classification script (no dropout)", "DiffusionNet's"): (
        "diffusionnet-nodropout"
    ),
    ("DiffusionNet, as its public classification script (no dropout)", "copies"): "diffusionnet-nodropout",
    ("`EdgeFieldNet(log_features=True)`", "DiffusionNet's"): "edgefieldnet",
    ('ablation: without the vector stream (`vector="none"`)', "copies"): "edgefieldnet-scalar",
    ('ablation: vertex gradients instead of edge fields (`vector="vertex"`)', "copies"): (
        "edgefieldnet-vertexvec"
    ),
    ("ablation: diffusion times not learned (`learn_times=False`)", "copies"): "edgefieldnet-fixedtime",
    ('ablation: without the vector stream (`vector="none"`)', "DiffusionNet's"): "edgefieldnet-scalar",
    ('ablation: vertex gradients instead of edge fields (`vector="vertex"`)', "DiffusionNet's"): (
        "edgefieldnet-vertexvec"
    ),
    ("ablation: diffusion times not learned (`learn_times=False`)", "DiffusionNet's"): (
        "edgefieldnet-fixedtime"
    ),
    ('ablation: DiffusionNet\'s input and readout (`pool="mean"`, raw HKS)', "DiffusionNet's"): (
        "edgefieldnet-rawmean"
    ),
    ("DiffusionNet with dropout 0.5, log-HKS and the mean and deviation readout", "DiffusionNet's"): (
        "diffusionnet-logstd"
    ),
    ("`EdgeFieldNet(log_features=16)`, mean curvature input", "copies"): "edgefieldnet, mean curvature input",
    ("DiffusionNet, as its public classification script (no dropout), mean curvature input", "copies"): (
        "diffusionnet-nodropout, mean curvature input"
    ),
}


#: the rows of the top-level README's results table: the label of their runs
HEADLINE = {
    "**`EdgeFieldNet`**, recommended recipe": _NEW,
    "faithful DiffusionNet, recommended recipe": _ALIKE,
    "faithful DiffusionNet, its own recipe": "diffusionnet-nodropout",
}


def test_report_paired_table_is_that_of_the_saved_runs(bench, capsys):
    """The report's fold-by-fold comparison is what ``--table ... --paired`` prints."""
    runs = ROOT / "experiments/psb_classification/runs/runs.json"
    bench.main(["--table", str(runs), "--paired", bench.PAIRED_REFERENCE])
    printed = capsys.readouterr().out
    paired = printed[printed.index("Against ") :].strip()
    assert paired in (ROOT / "experiments/psb_classification/README.md").read_text()


def _saved(name: str) -> list[dict]:
    """The runs saved in the study's folder, ``experiments/psb_classification/NAME``."""
    return json.loads((STUDY / name).read_text())


def _joined(path: str) -> str:
    """The text of the repository's file ``path`` with its lines joined by single spaces,
    so that a phrase is found wherever the file breaks its lines."""
    return " ".join((ROOT / path).read_text().split())


def _seed(r):
    return r["seed"]


def _fold_counts(bench, rows, label, seed) -> dict[str, int]:
    """Correct of 76 per fold (``"fold0"``, ...) of partition 0 for the runs of ``seed``
    labelled ``label`` (``rows`` through ``bench.with_averaged``)."""
    return {
        r["split"]: round(r["test_accuracy"] * 76)
        for r in rows
        if bench.label(r) == label
        and r["seed"] == seed
        and r.get("partition", 0) == 0
        and r["split"].startswith("fold")
    }


def test_readme_p_values_are_those_of_the_saved_runs(bench):
    """The p-values in the README's reading are those of ``--paired`` on the saved runs,
    against this release's runs and against the earlier ones (``bench.PAIRED_REFERENCE``), on
    partition 0's folds (``--partitions 0``) or on those of every partition."""
    runs = bench.with_averaged(_saved("runs/runs.json"))
    readme = _joined(README)  # lines joined

    tables = {
        (reference, partitions): paired_rows(
            bench.paired_table(
                runs if partitions is None else bench.in_partitions(runs, partitions),
                reference or bench.PAIRED_REFERENCE,
            )
        )
        for reference, partitions in {
            (reference, partitions) for reference, partitions, _, _ in README_P_VALUES
        }
    }
    for reference, partitions, phrase, rows in README_P_VALUES:
        cells = tables[reference, partitions]
        assert phrase.format(*(cells[row][-1] for row in rows)) in readme, phrase


def holm(p_values: list[float]) -> list[float]:
    """Holm's step-down adjustment of a family of p-values, in their order."""
    order = sorted(range(len(p_values)), key=p_values.__getitem__)
    adjusted, running = [0.0] * len(p_values), 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (len(p_values) - rank) * p_values[i]))
        adjusted[i] = running
    return adjusted


def test_holm_adjustment_by_hand():
    # sorted 0.01, 0.02, 0.04 times 3, 2, 1: 0.03, 0.04, 0.04 (kept monotone)
    assert holm([0.04, 0.01, 0.02]) == pytest.approx([0.04, 0.03, 0.04])
    assert holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])


def test_readme_holm_adjusted_p_values_are_those_of_the_saved_runs(bench):
    """The README's Holm-adjusted p-values of the three ablations, over the folds of every
    partition, follow from the p-values that ``--paired`` prints for them."""
    runs = bench.with_averaged(_saved("runs/runs.json"))
    readme = _joined(README)
    cells = paired_rows(bench.paired_table(runs, RERUN))
    adjusted = holm([float(cells[a][-1].lstrip("<")) for a in _ABLATIONS])
    a, b, c = (f"{p:.3f}" for p in adjusted)
    assert f"Holm-adjusted p = {a}, {b} and {c}" in readme
    assert f"Holm's adjustment: {a}, {b} and {c}" in readme


def test_readme_summary_is_that_of_the_saved_runs(bench):
    """The accuracies of the README's short verdicts: every test mesh of seeds 0-2 on the
    fixed split, or on the five folds of partition 0."""
    runs = bench.with_averaged(_saved("runs/runs.json"))
    readme = _joined(README)

    def accuracy(label: str, split: str) -> str:
        mine = [
            r
            for r in runs
            if bench.label(r) == label
            and r["seed"] in (0, 1, 2)
            and r.get("partition", 0) == 0
            and (r["split"] == "fixed" if split == "fixed" else r["split"].startswith("fold"))
        ]
        assert len(mine) == (3 if split == "fixed" else 15), (label, split, len(mine))
        return f"{sum(r['test_accuracy'] for r in mine) / len(mine):.3f}"

    for phrase, rows in README_SUMMARY:
        assert phrase.format(*(accuracy(*row) for row in rows)) in readme, phrase


def test_readme_learning_table_is_that_of_the_saved_runs(bench):
    """Every cell of the README's learning table comes from the saved runs: the fixed split's
    mean and deviation over seeds 0-2 (and over seeds 0-5 where they were run), each seed's
    mean and deviation over the 5 folds (every seed and ``--partition`` whose 5 folds were run), "not run"
    where there are none, and the parameters; the time per step from the saved
    ``--step-time`` measurement, as a ratio to the faithful DiffusionNet's."""
    runs = bench.with_averaged(_saved("runs/runs.json"))
    readme = (ROOT / README).read_text()
    section = readme[readme.index("## Results") : readme.index("## The command and its options")]
    rows = [
        [c.strip().strip("*") for c in line.strip("|").split("|")]
        for line in section.splitlines()
        if line.startswith("| ") and not line.startswith("| model")
    ]

    def key(model: str, recipe: str) -> tuple[str, str]:  # the README_ROWS entry of a row
        return model, recipe if recipe == "DiffusionNet's" else "copies"

    assert {key(m, r) for m, r, *_ in rows} == set(README_ROWS)
    assert len({(m, r) for m, r, *_ in rows}) == len(rows)  # no row twice

    def mean_std(xs: list[float]) -> str:
        return f"{statistics.mean(xs):.3f} ± {statistics.stdev(xs):.3f}"

    def ratios(file: str) -> dict[str, float]:  # each model's mean step over the baseline's
        steps = {r["model"]: statistics.mean(r["seconds_per_step"]) for r in _saved(file)}
        return {m: t / steps[bench.BASELINE] for m, t in steps.items()}

    # a network measured later: its own measurement against the baseline in the same process
    steps = ratios("runs/step_times_3.json") | ratios("runs/step_times.json")
    for model, recipe, fixed_cell, cross_cell, time_cell, parameters in rows:
        assert recipe in README_RECIPES, recipe
        network = README_ROWS[key(model, recipe)]
        name = network + README_RECIPES[recipe]
        # a row with an input other than the HKS: the time of its network on the HKS
        # (test_readme_curvature_input_costs_no_time)
        model_name = network.split(", ")[0]
        assert time_cell == f"{steps[model_name]:.2f}", name
        mine = [r for r in runs if bench.label(r) == name]
        seeds = sorted((r["seed"], r["test_accuracy"]) for r in mine if r["split"] == "fixed")
        fixed = [a for _, a in seeds]
        if fixed_cell == "not run":
            assert not fixed, name
        elif fixed_cell.endswith("(one seed)"):
            assert fixed_cell == f"{fixed[0]:.3f} (one seed)" and len(fixed) == 1, name
        else:  # seeds 0-2 (the target's), then all six where seeds 3-5 were run too
            first, _, six = fixed_cell.partition("; seeds 0-5: ")
            first = first.strip("*")
            assert [s for s, _ in seeds] == list(range(6 if six else 3)), name
            assert first == mean_std([a for s, a in seeds if s < 3]), name
            assert six in ("", mean_std(fixed)), name
        folds = {}  # (partition, seed): accuracies over the folds
        for r in mine:
            if r["split"].startswith("fold"):
                folds.setdefault((r.get("partition", 0), r["seed"]), []).append(r["test_accuracy"])

        def run_name(part: int, seed: int) -> str:
            return (f"partition {part}, " if part else "") + (
                f"seed {seed}: " if (part, seed) != (0, 0) else ""
            )

        complete = [run_name(*key) + mean_std(xs) for key, xs in sorted(folds.items()) if len(xs) == 5]
        if cross_cell == "not run":
            assert not folds, name
        elif cross_cell.endswith("(fold 0 only)"):
            assert cross_cell == f"{folds[0, 0][0]:.3f} (fold 0 only)" and len(folds[0, 0]) == 1, name
        else:
            assert [c.strip("*") for c in cross_cell.split("; ")] == complete, name
        assert {f"{r['parameters']:,}" for r in mine} == {parameters}, name


def test_readme_bearings_with_holes_are_those_of_the_saved_runs(bench, psb):
    """The README's count of the fixed split's bearings with holes that each network
    classifies, over every saved run that recorded each mesh's class (the runs file and the
    re-runs of ``runs/fixed_meshes.json``), averaged weights."""
    runs = _saved("runs/runs.json")
    reruns = _saved("runs/fixed_meshes.json")
    dataset = bench.load_psb(psb)
    labels, classes = dataset["labels"], np.array(dataset["classes"])
    euler = euler_of_closed(dataset)
    holes = [
        i for i in np.flatnonzero(dataset["split"] == 1) if classes[labels[i]] == "bearing" and euler[i] != 2
    ]
    assert (
        len(holes) == 3
        and not ((classes[labels] == "bearing") & (euler != 2) & (dataset["split"] == 0)).any()
    )

    def count(model, rs, meshes):  # (right, pairs) of the model's fixed-split runs on these meshes
        right = pairs = 0
        for r in rs:
            if r["model"] == model and r["split"] == "fixed" and "averaged_test_predictions" in r:
                for m, p in zip(r["test_meshes"], r["averaged_test_predictions"]):
                    if m in meshes:
                        right, pairs = right + int(p == labels[m]), pairs + 1
        return right, pairs

    full, scalar = (
        count("edgefieldnet", runs + reruns, holes),
        count("edgefieldnet-scalar", runs + reruns, holes),
    )
    others = [i for i in np.flatnonzero(dataset["split"] == 1) if i not in holes]
    level = count("edgefieldnet", reruns, others), count("edgefieldnet-scalar", reruns, others)
    assert level[0] == level[1]
    readme = _joined(README)
    phrase = (
        f"the full network classifies {full[0]} of their {full[1]} (mesh, run) pairs (with or without the "
        f"curvature input), the network without the vector stream {scalar[0]} of {scalar[1]}; on the other "
        f"{len(others)} test meshes the two are level ({level[0][0]} of {level[0][1]} each)."
    )
    assert phrase in readme


def test_readme_topology_shift_is_that_of_the_saved_runs(bench, psb):
    """The README's counts on the split across topology: test meshes classified over seeds
    0-2 with the averaged weights, in all and among the cups, for each network."""
    runs = _saved("runs/topology_runs.json")
    dataset = bench.load_psb(psb)
    labels, classes = dataset["labels"], np.array(dataset["classes"])
    flags = bench.topology_shift_flags(dataset)

    def counts(model):  # (right in all, right among the cups), over seeds 0-2
        mine = [r for r in runs if r["model"] == model and r["seed"] in (0, 1, 2)]
        assert sorted(r["seed"] for r in mine) == [0, 1, 2] and all(r["split"] == "topology" for r in mine)
        right = cups = 0
        for r in mine:
            assert sorted(r["test_meshes"]) == np.flatnonzero(flags).tolist()
            for m, p in zip(r["test_meshes"], r["averaged_test_predictions"]):
                right += int(p == labels[m])
                cups += int(p == labels[m] and classes[labels[m]] == "cup")
        return right, cups

    (e, ec), (s, sc), (v, vc), (d, dc) = map(
        counts, ["edgefieldnet", "edgefieldnet-scalar", "edgefieldnet-vertexvec", "diffusionnet-nodropout"]
    )
    phrases = {
        README: f"the edge-field network classifies {e} of 117 (seeds 0-2), the same network without "
        f"its vector stream {s}, with vertex gradients {v} and DiffusionNet trained alike {d}; among the 48 "
        f"cups, {ec} against {sc}, {vc} and {dc}.",
    }
    for path, phrase in phrases.items():
        assert phrase in _joined(path), (path, phrase)


def test_report_topology_table_is_that_of_the_saved_runs(bench, psb):
    """Every row of the report's table across topology: correct test meshes per seed and in
    all (averaged weights), with the final weights, and per group of classes, from the
    saved runs of each network."""
    runs = _saved("runs/topology_runs.json")
    dataset = bench.load_psb(psb)
    labels, classes = dataset["labels"], np.array(dataset["classes"])
    report = _joined("experiments/psb_classification/README.md")
    for model in dict.fromkeys(r["model"] for r in runs):
        mine = sorted((r for r in runs if r["model"] == model), key=_seed)
        assert [r["seed"] for r in mine] == [0, 1, 2], model
        per_seed, final, groups = [], 0, {"cup": 0, "vase": 0, "bearing": 0, "other": 0}
        for r in mine:
            right = [p == labels[m] for m, p in zip(r["test_meshes"], r["averaged_test_predictions"])]
            per_seed.append(sum(right))
            final += sum(p == labels[m] for m, p in zip(r["test_meshes"], r["test_predictions"]))
            for m, ok in zip(r["test_meshes"], right):
                group = classes[labels[m]]
                groups[group if group in groups else "other"] += int(ok)
        cells = [*map(str, per_seed), f"{sum(per_seed)} of 117", str(final)]
        cells += [
            f"{groups[g]} of {n}" for g, n in (("cup", 48), ("vase", 36), ("bearing", 9), ("other", 24))
        ]
        row = " | ".join(cells) + " |"
        assert any(f"| `{model}`{tail} | {row}" in report for tail in ("", " (run later)")), (model, row)


def test_readme_curvature_input_costs_no_time():
    """The README's rows with the mean curvature input take the time of their network on
    the HKS alone, as it says: in the saved measurement, alternated with the HKS input,
    each network's step is within 5% of its step on the HKS."""
    readme = _joined(README)
    assert "the 9 extra channels cost no measurable time (within 5%" in readme
    saved = _saved("runs/step_times_curvature.json")
    for model in ("edgefieldnet", "diffusionnet-nodropout"):
        step = {
            i: statistics.mean(
                t for r in saved if (r["model"], r["input"]) == (model, i) for t in r["seconds_per_step"]
            )
            for i in ("hks", "hks+curvature")
        }
        assert abs(step["hks+curvature"] / step["hks"] - 1) < 0.05, (model, step)


def test_report_topology_validation_table_is_that_of_the_saved_runs(bench, psb):
    """Each row of the report's table on the topology validation split: per seed the test
    meshes classified with the averaged / final weights, their sums, and the cups and vases
    classified (averaged weights), from the saved runs."""
    runs = _saved("runs/topology_validation_runs.json")
    dataset = bench.load_psb(psb)
    labels, classes = dataset["labels"], np.array(dataset["classes"])
    flags = bench.topology_shift_flags(dataset, validation=True)
    report = (ROOT / "experiments/psb_classification/README.md").read_text()
    for model in dict.fromkeys(r["model"] for r in runs):
        mine = sorted((r for r in runs if r["model"] == model), key=lambda r: r["seed"])
        assert [r["seed"] for r in mine] == [0, 1, 2] and all(
            r["split"] == "topology validation" for r in mine
        )
        cells, sums = [], {"averaged_test_predictions": 0, "test_predictions": 0, "cup": 0, "vase": 0}
        for r in mine:
            assert sorted(r["test_meshes"]) == np.flatnonzero(flags == 1).tolist()
            right = {}
            for key in ("averaged_test_predictions", "test_predictions"):
                right[key] = sum(int(p == labels[m]) for m, p in zip(r["test_meshes"], r[key]))
                sums[key] += right[key]
            for c in ("cup", "vase"):
                sums[c] += sum(
                    int(p == labels[m] and classes[labels[m]] == c)
                    for m, p in zip(r["test_meshes"], r["averaged_test_predictions"])
                )
            cells.append(f"{right['averaged_test_predictions']} / {right['test_predictions']}")
        row = f"| `{model}` | " + " | ".join(cells) + " | "
        assert row in report, row
        tail = report[report.index(row) + len(row) :].split("\n")[0]
        numbers = [int(x) for x in tail.replace("*", "").strip(" |").split(" | ")]
        assert numbers == [sums[k] for k in ("averaged_test_predictions", "test_predictions", "cup", "vase")]


def _per_run(runs, model, split, key, seeds=(0, 1, 2), size=76):
    """The runs of ``model`` on the splits whose name starts with ``split``, of ``seeds``,
    ordered by ``key``: their keys and their (averaged, final) correct of ``size``."""
    mine = sorted(
        (r for r in runs if r["model"] == model and r["split"].startswith(split) and r["seed"] in seeds),
        key=key,
    )
    return [key(r) for r in mine], [
        (round(r["averaged_test_accuracy"] * size), round(r["test_accuracy"] * size)) for r in mine
    ]


def _validation_row(runs, model, bound=200):
    """The validation row of a candidate's results table (seeds 0-2 against the rule's
    ``bound``), and the candidate's (averaged, final) correct of 76 per seed."""
    keys, pairs = _per_run(runs, model, "validation", _seed)
    assert keys == [0, 1, 2], model
    row = "| validation (of 228) | " + " | ".join(f"{a} / {f}" for a, f in pairs)
    return row + f" | **{sum(a for a, _ in pairs)}** | {sum(f for _, f in pairs)} | at least {bound} |", pairs


def test_report_meanpool_candidate_is_that_of_the_saved_runs():
    """The report's validation row and fixed-split counts of the candidate with
    DiffusionNet's readout: correct of 76 per seed with the averaged / final weights, and
    the sums, from the runs file."""
    runs = _saved("runs/runs.json")
    report = _joined("experiments/psb_classification/README.md")
    row, _ = _validation_row(runs, "edgefieldnet-meanpool")
    assert row in report, row
    keys, pairs = _per_run(runs, "edgefieldnet-meanpool", "fixed", _seed)
    assert keys == [0, 1, 2]
    phrase = "On the fixed split (seeds 0, 1, 2), correct of 76 with the averaged / final weights: "
    phrase += ", ".join(f"{a} / {f}" for a, f in pairs[:2]) + f" and {pairs[2][0]} / {pairs[2][1]}. "
    averaged = sum(a for a, _ in pairs)
    phrase += f"**{averaged} of 228 ({averaged / 228:.3f}) with the recommended averaged weights"
    assert phrase in report, phrase
    keys, pairs = _per_run(runs, "edgefieldnet-meanpool", "fold", lambda r: r["split"], seeds=(0,))
    assert keys == [f"fold{k}" for k in range(5)]
    row = f"| `edgefieldnet-meanpool` | {', '.join(str(a) for a, _ in pairs)} | "
    row += f"**{sum(a for a, _ in pairs)}** (final weights {sum(f for _, f in pairs)}) |"
    assert row in report, row


def test_report_meanpool_folds_and_rule_are_those_of_the_saved_runs(bench):
    """The fold table of the network with DiffusionNet's readout, its three references and
    its network without the vector stream (partition 0, correct of 76 per fold), and the
    rule's verdict, from the runs file."""
    runs = bench.with_averaged(_saved("runs/runs.json"))
    report = _joined("experiments/psb_classification/README.md")
    copies = "4 stretched copies"

    def folds(name, seed):  # correct of 76 on folds 0-4 of partition 0
        mine = _fold_counts(bench, runs, name, seed)
        assert sorted(mine) == [f"fold{k}" for k in range(5)], (name, seed)
        return [mine[f"fold{k}"] for k in range(5)]

    def row(cell, name, seeds=(0, 1, 2)):
        per = [folds(name, s) for s in seeds]
        cells = " | ".join(", ".join(map(str, f)) for f in per)
        return f"| {cell} | {cells} |", sum(map(sum, per))

    mean, mean_total = row("`edgefieldnet-meanpool`", f"edgefieldnet-meanpool, {copies}, averaged last 10")
    _, final_total = row("", f"edgefieldnet-meanpool, {copies}")
    assert f"{mean} **{mean_total:,}** (final weights {final_total:,}) |" in report
    ours, ours_total = row(
        "`edgefieldnet`, the recommended recipe", f"edgefieldnet, {copies}, coefficients, averaged last 10"
    )
    alike, alike_total = row(
        "faithful DiffusionNet, trained alike", f"diffusionnet-nodropout, {copies}, averaged last 10"
    )
    own, own_total = row("faithful DiffusionNet, its own recipe (final weights)", "diffusionnet-nodropout")
    for line, total in ((ours, ours_total), (alike, alike_total), (own, own_total)):
        assert f"{line} {total:,} |" in report, line
    without = f"edgefieldnet-meanpool-scalar, {copies}, averaged last 10"
    scalar, scalar_total = row("`edgefieldnet-meanpool-scalar` (no vector stream)", without, (0,))
    assert f"{scalar} | | {scalar_total} of 380 |" in report
    for cell, name in (("vertex gradients", "vertexvec"), ("times frozen", "fixedtime")):
        line, total = row(
            f"`edgefieldnet-meanpool-{name}` ({cell})",
            f"edgefieldnet-meanpool-{name}, {copies}, averaged last 10",
            (0,),
        )
        assert f"{line} | | {total} of 380 |" in report, line
    bound = ours_total - 6  # the rule: the recommended network's count less two a seed
    mean_seed0 = folds(f"edgefieldnet-meanpool, {copies}, averaged last 10", 0)
    lower = sum(a < b for a, b in zip(folds(without, 0), mean_seed0))
    assert f"at least {bound:,} of 1,140" in report
    verdict = '**`pool="mean"` does not become the recommended network**'
    assert (mean_total >= bound and lower >= 4) != (verdict in report)


def test_report_combined_candidate_is_that_of_the_saved_runs():
    """The validation row of the candidate with both changes (the fields not diffused,
    DiffusionNet's readout), and its verdict, from the runs file."""
    runs = _saved("runs/runs.json")
    report = _joined("experiments/psb_classification/README.md")
    row, pairs = _validation_row(runs, "edgefieldnet-local-meanpool")
    assert row in report, row
    assert sum(a for a, _ in pairs) < 200 and "**The combined candidate is rejected**" in report


def test_report_nodiv_candidates_are_those_of_the_saved_runs():
    """The results table of the two networks without the divergence and curl (alone and
    with DiffusionNet's readout) on both validation splits, and which passes the rule."""
    report = _joined("experiments/psb_classification/README.md")
    runs = {
        "topology validation (of 93)": (_saved("runs/topology_validation_runs.json"), 41),
        "validation (of 228)": (_saved("runs/runs.json"), 200),
    }
    passed = []
    for model in ("edgefieldnet-nodiv", "edgefieldnet-nodiv-meanpool"):
        ok = True
        for split, (rs, bound) in runs.items():
            size = 31 if split.startswith("topology") else 76
            keys, pairs = _per_run(rs, model, split.split(" (")[0], _seed, size=size)
            assert keys == [0, 1, 2], (model, split)
            averaged = sum(a for a, _ in pairs)
            row = f"| `{model}` | {split} | " + " | ".join(f"{a} / {f}" for a, f in pairs)
            row += f" | **{averaged}** | {sum(f for _, f in pairs)} | at least {bound} |"
            assert row in report, row
            ok = ok and averaged >= bound
        passed.append(ok)
    assert passed == [False, True]
    assert "**`edgefieldnet-nodiv` fails the second part of the rule**" in report
    assert "**`edgefieldnet-nodiv-meanpool` passes both parts**" in report
    keys, pairs = _per_run(runs["validation (of 228)"][0], "edgefieldnet-nodiv-meanpool", "fixed", _seed)
    assert keys == [0, 1, 2]
    phrase = "On the fixed split (seeds 0, 1, 2), correct of 76 with the averaged / final weights: "
    phrase += ", ".join(f"{a} / {f}" for a, f in pairs[:2]) + f" and {pairs[2][0]} / {pairs[2][1]}. "
    averaged, final = sum(a for a, _ in pairs), sum(f for _, f in pairs)
    phrase += f"**{averaged} of 228 ({averaged / 228:.3f}) with the recommended averaged weights: the "
    phrase += "0.90 target is met, with nothing to spare**; "
    phrase += f"with the final weights {final} ({final / 228:.3f})."
    assert averaged >= 0.90 * 228 and phrase in report, phrase


def test_recommended_network_folds_ablations_and_trade_are_those_of_the_saved_runs(bench):
    """The recommended network's fold table and verdict in the report, and the README's
    ablation counts (seed 0) and its trade against the previous recommendation: the folds
    of seeds 0-2, the fixed split and the split across topology, averaged weights."""
    rows = bench.with_averaged(_saved("runs/runs.json"))
    mine = {s: _fold_counts(bench, rows, _NEW, s) for s in (0, 1, 2)}
    before = {s: _fold_counts(bench, rows, RERUN, s) for s in (0, 1, 2)}
    assert all(len(mine[s]) == len(before[s]) == 5 for s in (0, 1, 2))
    total, total_before = (sum(sum(d[s].values()) for s in (0, 1, 2)) for d in (mine, before))
    row = "| `edgefieldnet-nodiv-meanpool` | " + " | ".join(
        ", ".join(str(mine[s][f"fold{k}"]) for k in range(5)) for s in (0, 1, 2)
    )
    report = _joined("experiments/psb_classification/README.md")
    assert row + f" | **{total:,}** (final weights" in report, row
    dn = {s: _fold_counts(bench, rows, "diffusionnet-nodropout", s) for s in (0, 1, 2)}
    dn_total = sum(sum(dn[s].values()) for s in (0, 1, 2))
    assert total >= dn_total and f"1. the cross-validation target: {total:,} of 1,140" in report

    def fixed(label):
        return sum(
            round(r["test_accuracy"] * 76)
            for r in rows
            if bench.label(r) == label and r["split"] == "fixed" and r["seed"] < 3
        )

    across = collections.Counter()
    for r in _saved("runs/topology_validation_runs.json"):
        if r["model"] in ("edgefieldnet-nodiv-meanpool", "edgefieldnet"):
            across[r["model"]] += round(r["averaged_test_accuracy"] * 31)
    scalar, vertex, frozen = (
        _fold_counts(bench, rows, f"edgefieldnet-{a}, 4 stretched copies, averaged last 10", 0)
        for a in ("meanpool-scalar", "meanpool-vertexvec", "nodiv-meanpool-fixedtime")
    )
    assert all(d[k] < mine[0][k] for d in (scalar, frozen) for k in d) and len(scalar) == len(frozen) == 5
    phrase = (
        f"without the vector stream it classifies {sum(scalar.values())} against {sum(mine[0].values())} "
        f"(fewer on all 5 folds), with DiffusionNet's vertex gradients in place of the edge operators "
        f"{sum(vertex.values())}, and with the diffusion times frozen {sum(frozen.values())} (fewer on all "
        f"5 folds)."
    )
    assert f"and with its diffusion times frozen too ({sum(frozen.values())})." in _joined(README)
    frozen_row = ", ".join(str(frozen[f"fold{k}"]) for k in range(5))
    assert f"| `edgefieldnet-nodiv-meanpool-fixedtime` (times frozen) | {frozen_row} | | | " in report
    readme = _joined(README)
    assert phrase in readme, phrase
    phrase = (
        f"The previous recommendation (below) classifies {total_before - total} more of the folds' meshes "
        f"and {fixed(_NEW) - fixed(RERUN)} fewer of the fixed split's; on the split across topology inside "
        f"the training meshes the new one classifies {across['edgefieldnet-nodiv-meanpool']} of 93 against "
        f"its {across['edgefieldnet']}"
    )
    assert phrase in readme, phrase


def test_readme_meanpool_readout_is_that_of_the_saved_runs(bench):
    """The README's counts for the network with DiffusionNet's readout and its two
    references: seeds 0-2 on the topology validation split, the validation split and the
    fixed split, and seed 0 of the folds of partition 0, averaged weights."""
    runs = bench.with_averaged(_saved("runs/runs.json"))
    across = bench.with_averaged(_saved("runs/topology_validation_runs.json"))
    mean = "edgefieldnet-meanpool, 4 stretched copies, averaged last 10"
    alike = "diffusionnet-nodropout, 4 stretched copies, averaged last 10"

    def right(rs, name, split, seeds=(0, 1, 2)):  # correct test meshes summed over the runs
        mine = [
            r for r in rs if bench.label(r) == name and r["split"] == split and r.get("partition", 0) == 0
        ]
        mine = [r for r in mine if r["seed"] in seeds]
        assert sorted(r["seed"] for r in mine) == sorted(seeds), (name, split)
        size = 31 if split == "topology validation" else 76  # older runs did not record their meshes
        return sum(round(r["test_accuracy"] * size) for r in mine)

    def folds(name):  # accuracy over the folds of seeds 0-2
        return sum(right(runs, name, f"fold{k}", (s,)) for k in range(5) for s in (0, 1, 2)) / 1140

    logstd = "diffusionnet-logstd, 4 stretched copies, averaged last 10"
    t = [right(across, n, "topology validation") for n in (mean, RERUN, alike, logstd)]
    v = [right(runs, n, "validation") for n in (mean, RERUN)]
    f = [right(runs, n, "fixed") / 228 for n in (mean, RERUN)]
    c = [folds(n) for n in (mean, RERUN, alike)]
    w = collections.Counter()  # correct of the 39 test meshes across topology, seeds 0-2, by model
    for r in _saved("runs/topology_runs.json"):
        w[r["model"]] += round(r["averaged_test_accuracy"] * 39)
    apart = sorted(w[n] for n in ("edgefieldnet-scalar", "edgefieldnet-vertexvec", "diffusionnet-nodropout"))
    phrase = (
        f"the same network classifies {t[0]} of 93 on a split across topology inside the training "
        f"meshes (`--topology-shift --validation`; the previous recommendation {t[1]}, DiffusionNet "
        f"trained alike {t[2]}; DiffusionNet with the mean and deviation readout {t[3]}), {v[0]} of 228 "
        f"on the validation split ({v[1]}) and {f[0]:.3f} on the fixed split ({f[1]:.3f}; the 0.90 "
        f"target is still missed); {w['edgefieldnet-meanpool']} of 117 on the whole split across "
        f"topology ({w['edgefieldnet']}; without edge fields {apart[0]}-{apart[-1]}). On the folds of 3 "
        f"seeds it classifies {c[0]:.3f} (the previous recommendation {c[1]:.3f}, DiffusionNet trained alike "
        f"{c[2]:.3f}): short of the bar"
    )
    readme = _joined(README)
    assert phrase in readme, phrase
    docs = (
        f"across topology ({t[0]} of 93 against {t[1]} on `--topology-shift --validation`, DiffusionNet "
        f"{t[2]}), at a small cost on the folds ({c[0]:.3f} against {c[1]:.3f} over 3 seeds; DiffusionNet "
        f"trained alike {c[2]:.3f})."
    )
    assert docs in _joined(README), docs
    assert f[0] < 0.9 and round(c[0] * 1140) < round(c[1] * 1140) - 6
    both = right(runs, "edgefieldnet-local-meanpool, 4 stretched copies, averaged last 10", "validation")
    assert (
        f"readout as well they do worse than either change ({both} of 228 on the validation split)" in readme
    )
    assert both < min(
        v[0], right(runs, "edgefieldnet-local, 4 stretched copies, averaged last 10", "validation")
    )


def test_readme_local_fields_on_the_fixed_split_are_those_of_the_saved_runs(bench, psb):
    """The README's count for the network whose fields are not diffused on the fixed split
    (seeds 0-2, averaged weights), in all and on the three bearings with holes."""
    runs = [r for r in _saved("runs/runs.json") if r["model"] == "edgefieldnet-local"]
    runs = [r for r in runs if r["split"] == "fixed"]
    assert sorted(r["seed"] for r in runs) == [0, 1, 2]
    dataset = bench.load_psb(psb)
    labels, classes = dataset["labels"], np.array(dataset["classes"])
    euler = euler_of_closed(dataset)
    right = holes = pairs = 0
    for r in runs:
        for m, p in zip(r["test_meshes"], r["averaged_test_predictions"]):
            right += int(p == labels[m])
            if classes[labels[m]] == "bearing" and euler[m] != 2:
                holes, pairs = holes + int(p == labels[m]), pairs + 1
    phrase = (
        f"classify {right} of 228 of the fixed split's test meshes ({right / 228:.3f}) and all {holes} "
        f"(mesh, seed) pairs of its bearings with holes;"
    )
    assert holes == pairs == 9 and phrase in _joined(README), phrase
    rows = bench.with_averaged(_saved("runs/runs.json"))
    local = _fold_counts(bench, rows, "edgefieldnet-local, 4 stretched copies, averaged last 10", 0)
    ours = _fold_counts(bench, rows, RERUN, 0)
    phrase = (
        f"on the {len(local)} folds of seed 0 they classify {sum(local.values())} of {76 * len(local)} "
        f"against the previous recommendation's {sum(ours[k] for k in local)}."
    )
    assert phrase in _joined(README), phrase
    docs = (
        f"on the {len(local)} folds of seed 0 it classifies {sum(local.values())} of {76 * len(local)} "
        f"against {sum(ours[k] for k in local)})."
    )
    assert docs in _joined(README), docs


def test_report_ablations_of_the_recommended_network_on_seed_1_are_those_of_the_saved_runs():
    runs = _saved("runs/runs.json")
    report = (ROOT / "experiments/psb_classification/README.md").read_text()
    section = report[report.index("## The recommended network's ablations on a second seed") :]
    seed_fold = lambda r: (r["seed"], r["split"])  # noqa: E731
    rows = {
        "edgefieldnet-nodiv-meanpool": "`edgefieldnet-nodiv-meanpool`, recommended",
        "edgefieldnet-meanpool-vertexvec": "`edgefieldnet-meanpool-vertexvec` (vertex gradients)",
        "edgefieldnet-meanpool-scalar": "`edgefieldnet-meanpool-scalar` (no vector stream)",
    }
    for model, name in rows.items():
        keys, both = _per_run(runs, model, "fold", seed_fold, seeds=(0, 1))
        assert keys == [(s, f"fold{k}") for s in (0, 1) for k in range(5)], model
        counts = both[5:]  # seed 1
        averaged = ", ".join(str(a) for a, _ in counts)
        total = sum(a for a, _ in counts)
        final = "" if model == "edgefieldnet-nodiv-meanpool" else f" ({sum(f for _, f in counts)})"
        row = f"| {name} | {averaged} | {total}{final} | {sum(a for a, _ in both)} |"
        assert row in section, row


def test_the_top_level_readme_headline_is_that_of_the_saved_runs(bench):
    """The README's results table: the mean over seeds 0-2 of the fixed split's accuracy,
    the accuracy over the 1,140 test meshes of the 5 folds of seeds 0-2 (partition 0), the
    time per step against the faithful DiffusionNet's and the parameters; and its verdicts:
    the lead over DiffusionNet's own recipe and its p-value, the meshes ahead and behind
    DiffusionNet trained alike, and the ablation of the vector stream on the folds of seed 0.
    docs/learning.md repeats the first and last rows."""
    runs = bench.with_averaged(_saved("runs/runs.json"))
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("## Results") : readme.index("## Performance")]
    section = section.split("<!-- table:rna -->")[0]  # the RNA headline is the RNA study's
    rows = {
        cells[0]: cells[1:]
        for line in section.splitlines()
        if line.startswith("| ") and not line.startswith("| network")
        for cells in [[c.strip() for c in line.strip("|").split("|")]]
    }
    assert set(rows) == set(HEADLINE)
    steps = {r["model"]: statistics.mean(r["seconds_per_step"]) for r in _saved("runs/step_times_3.json")}
    right = {}
    for row, label in HEADLINE.items():
        mine = [r for r in runs if bench.label(r) == label and r.get("partition", 0) == 0]
        fixed = [round(76 * r["test_accuracy"]) for r in mine if r["split"] == "fixed" and r["seed"] < 3]
        folds = [
            round(76 * r["test_accuracy"]) for r in mine if r["split"].startswith("fold") and r["seed"] < 3
        ]
        assert len(fixed) == 3 and len(folds) == 15, label
        right[row] = (sum(fixed), sum(folds))
        model = label.split(",")[0]
        want = [
            f"{sum(fixed) / 228:.3f}",
            f"{sum(folds) / 1140:.3f}",
            f"{steps[model] / steps[bench.BASELINE]:.2f}",
            f"{mine[0]['parameters']:,}",
        ]
        assert [c.strip("*") for c in rows[row]] == want, (row, want)
    new, alike, own = (right[r] for r in HEADLINE)
    assert new[0] > own[0] and new[1] > own[1]
    assert (new[0] - alike[0], alike[1] - new[1]) == (3, 2)
    printed = bench.paired_table(
        runs, own_label := "diffusionnet-nodropout"
    )  # every row against the own recipe
    p_new = (
        next(line for line in printed.splitlines() if line.startswith(f"| {_NEW} |")).split("|")[-2].strip()
    )
    joined = " ".join(readme.split())
    assert f"(on the folds not significantly, p = {p_new})" in joined, p_new
    assert "(3 test meshes ahead on the fixed split, 2 behind on the folds)" in joined
    scalar = _fold_counts(
        bench, runs, "edgefieldnet-meanpool-scalar, 4 stretched copies, averaged last 10", 0
    )
    full = _fold_counts(bench, runs, _NEW, 0)
    assert len(full) == len(scalar) == 5 and all(scalar[k] < full[k] for k in full)
    assert "Without its vector stream it loses on all 5 folds of seed 0." in joined
    assert own_label in HEADLINE.values()
    docs = " ".join((ROOT / "docs/learning.md").read_text().split())
    n, o = rows["**`EdgeFieldNet`**, recommended recipe"], rows["faithful DiffusionNet, its own recipe"]
    phrase = (
        f"classifies {n[0].strip('*')} of the fixed split's test meshes and {n[1].strip('*')} over 5 folds"
    )
    assert (
        phrase in docs
        and f"against the faithful DiffusionNet's {o[0]} and {o[1]} with its own recipe" in docs
    )
