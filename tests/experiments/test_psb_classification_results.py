"""experiments/psb_classification: the README's and the report's tables, p-values and verdicts are those of
the saved runs."""

import statistics

import numpy as np
import pytest

from study import (
    README,
    RECOMMENDED,
    RERUN,
    ROOT,
    euler_of_closed,
    fold_counts,
    joined_text,
    paired_rows,
    psb_data,
    psb_report,
    saved_runs,
    seed_of,
)
from study import run as command

_ALIKE = "diffusionnet-nodropout, 4 stretched copies, averaged last 10"
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
            (RECOMMENDED, "fixed"),
            (RECOMMENDED.removesuffix(", averaged last 10"), "fixed"),
            (RECOMMENDED, "folds"),
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
    "**`EdgeFieldNet`**, recommended recipe": RECOMMENDED,
    "faithful DiffusionNet, recommended recipe": _ALIKE,
    "faithful DiffusionNet, its own recipe": "diffusionnet-nodropout",
}


def test_report_paired_table_is_that_of_the_saved_runs(capsys):
    """The report's fold-by-fold comparison is what ``--table ... --paired`` prints."""
    runs = ROOT / "experiments/psb_classification/runs/runs.json"
    command.main(["--table", str(runs), "--paired", psb_report.PAIRED_REFERENCE])
    printed = capsys.readouterr().out
    paired = printed[printed.index("Against ") :].strip()
    assert paired in (ROOT / "experiments/psb_classification/README.md").read_text()


def test_readme_p_values_are_those_of_the_saved_runs():
    """The p-values in the README's reading are those of ``--paired`` on the saved runs,
    against this release's runs and against the earlier ones (``psb_report.PAIRED_REFERENCE``), on
    partition 0's folds (``--partitions 0``) or on those of every partition."""
    runs = psb_report.with_averaged(saved_runs("runs/runs.json"))
    readme = joined_text(README)  # lines joined

    tables = {
        (reference, partitions): paired_rows(
            psb_report.paired_table(
                runs if partitions is None else psb_report.in_partitions(runs, partitions),
                reference or psb_report.PAIRED_REFERENCE,
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


def test_readme_holm_adjusted_p_values_are_those_of_the_saved_runs():
    """The README's Holm-adjusted p-values of the three ablations, over the folds of every
    partition, follow from the p-values that ``--paired`` prints for them."""
    runs = psb_report.with_averaged(saved_runs("runs/runs.json"))
    readme = joined_text(README)
    cells = paired_rows(psb_report.paired_table(runs, RERUN))
    adjusted = holm([float(cells[a][-1].lstrip("<")) for a in _ABLATIONS])
    a, b, c = (f"{p:.3f}" for p in adjusted)
    assert f"Holm-adjusted p = {a}, {b} and {c}" in readme
    assert f"Holm's adjustment: {a}, {b} and {c}" in readme


def test_readme_summary_is_that_of_the_saved_runs():
    """The accuracies of the README's short verdicts: every test mesh of seeds 0-2 on the
    fixed split, or on the five folds of partition 0."""
    runs = psb_report.with_averaged(saved_runs("runs/runs.json"))
    readme = joined_text(README)

    def accuracy(label: str, split: str) -> str:
        mine = [
            r
            for r in runs
            if psb_report.label(r) == label
            and r["seed"] in (0, 1, 2)
            and r.get("partition", 0) == 0
            and (r["split"] == "fixed" if split == "fixed" else r["split"].startswith("fold"))
        ]
        assert len(mine) == (3 if split == "fixed" else 15), (label, split, len(mine))
        return f"{sum(r['test_accuracy'] for r in mine) / len(mine):.3f}"

    for phrase, rows in README_SUMMARY:
        assert phrase.format(*(accuracy(*row) for row in rows)) in readme, phrase


def test_readme_learning_table_is_that_of_the_saved_runs():
    """Every cell of the README's learning table comes from the saved runs: the fixed split's
    mean and deviation over seeds 0-2 (and over seeds 0-5 where they were run), each seed's
    mean and deviation over the 5 folds (every seed and ``--partition`` whose 5 folds were run), "not run"
    where there are none, and the parameters; the time per step from the saved
    ``--step-time`` measurement, as a ratio to the faithful DiffusionNet's."""
    runs = psb_report.with_averaged(saved_runs("runs/runs.json"))
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
        steps = {r["model"]: statistics.mean(r["seconds_per_step"]) for r in saved_runs(file)}
        return {m: t / steps[psb_report.BASELINE] for m, t in steps.items()}

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
        mine = [r for r in runs if psb_report.label(r) == name]
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


def test_readme_bearings_with_holes_are_those_of_the_saved_runs(psb):
    """The README's count of the fixed split's bearings with holes that each network
    classifies, over every saved run that recorded each mesh's class (the runs file and the
    re-runs of ``runs/fixed_meshes.json``), averaged weights."""
    runs = saved_runs("runs/runs.json")
    reruns = saved_runs("runs/fixed_meshes.json")
    dataset = psb_data.load_psb(psb)
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
    readme = joined_text(README)
    phrase = (
        f"the full network classifies {full[0]} of their {full[1]} (mesh, run) pairs (with or without the "
        f"curvature input), the network without the vector stream {scalar[0]} of {scalar[1]}; on the other "
        f"{len(others)} test meshes the two are level ({level[0][0]} of {level[0][1]} each)."
    )
    assert phrase in readme


def test_readme_topology_shift_is_that_of_the_saved_runs(psb):
    """The README's counts on the split across topology: test meshes classified over seeds
    0-2 with the averaged weights, in all and among the cups, for each network."""
    runs = saved_runs("runs/topology_runs.json")
    dataset = psb_data.load_psb(psb)
    labels, classes = dataset["labels"], np.array(dataset["classes"])
    flags = psb_data.topology_shift_flags(dataset)

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
        assert phrase in joined_text(path), (path, phrase)


def test_report_topology_table_is_that_of_the_saved_runs(psb):
    """Every row of the report's table across topology: correct test meshes per seed and in
    all (averaged weights), with the final weights, and per group of classes, from the
    saved runs of each network."""
    runs = saved_runs("runs/topology_runs.json")
    dataset = psb_data.load_psb(psb)
    labels, classes = dataset["labels"], np.array(dataset["classes"])
    report = joined_text("experiments/psb_classification/README.md")
    for model in dict.fromkeys(r["model"] for r in runs):
        mine = sorted((r for r in runs if r["model"] == model), key=seed_of)
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
    readme = joined_text(README)
    assert "the 9 extra channels cost no measurable time (within 5%" in readme
    saved = saved_runs("runs/step_times_curvature.json")
    for model in ("edgefieldnet", "diffusionnet-nodropout"):
        step = {
            i: statistics.mean(
                t for r in saved if (r["model"], r["input"]) == (model, i) for t in r["seconds_per_step"]
            )
            for i in ("hks", "hks+curvature")
        }
        assert abs(step["hks+curvature"] / step["hks"] - 1) < 0.05, (model, step)


def test_report_topology_validation_table_is_that_of_the_saved_runs(psb):
    """Each row of the report's table on the topology validation split: per seed the test
    meshes classified with the averaged / final weights, their sums, and the cups and vases
    classified (averaged weights), from the saved runs."""
    runs = saved_runs("runs/topology_validation_runs.json")
    dataset = psb_data.load_psb(psb)
    labels, classes = dataset["labels"], np.array(dataset["classes"])
    flags = psb_data.topology_shift_flags(dataset, validation=True)
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


def test_the_top_level_readme_headline_is_that_of_the_saved_runs():
    """The README's results table: the mean over seeds 0-2 of the fixed split's accuracy,
    the accuracy over the 1,140 test meshes of the 5 folds of seeds 0-2 (partition 0), the
    time per step against the faithful DiffusionNet's and the parameters; and its verdicts:
    the lead over DiffusionNet's own recipe and its p-value, the meshes ahead and behind
    DiffusionNet trained alike, and the ablation of the vector stream on the folds of seed 0.
    docs/learning.md repeats the first and last rows."""
    runs = psb_report.with_averaged(saved_runs("runs/runs.json"))
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
    steps = {r["model"]: statistics.mean(r["seconds_per_step"]) for r in saved_runs("runs/step_times_3.json")}
    right = {}
    for row, label in HEADLINE.items():
        mine = [r for r in runs if psb_report.label(r) == label and r.get("partition", 0) == 0]
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
            f"{steps[model] / steps[psb_report.BASELINE]:.2f}",
            f"{mine[0]['parameters']:,}",
        ]
        assert [c.strip("*") for c in rows[row]] == want, (row, want)
    new, alike, own = (right[r] for r in HEADLINE)
    assert new[0] > own[0] and new[1] > own[1]
    assert (new[0] - alike[0], alike[1] - new[1]) == (3, 2)
    printed = psb_report.paired_table(
        runs, own_label := "diffusionnet-nodropout"
    )  # every row against the own recipe
    p_new = (
        next(line for line in printed.splitlines() if line.startswith(f"| {RECOMMENDED} |"))
        .split("|")[-2]
        .strip()
    )
    joined = " ".join(readme.split())
    assert f"(on the folds not significantly, p = {p_new})" in joined, p_new
    assert "(3 test meshes ahead on the fixed split, 2 behind on the folds)" in joined
    scalar = fold_counts(runs, "edgefieldnet-meanpool-scalar, 4 stretched copies, averaged last 10", 0)
    full = fold_counts(runs, RECOMMENDED, 0)
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
