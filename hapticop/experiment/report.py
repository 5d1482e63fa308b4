"""An experiment's results judged cell by cell against its targets, with confidence intervals, and drawn:
one Markdown page and its PNG pictures.

A fraction (`all`, `fraction`: how many runs pass) gets Wilson's 95 % interval, which stays inside [0, 1]
and is honest for a handful of runs; a `mean` gets Student's t interval."""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa

from hapticop.experiment.description import Experiment, Target
from hapticop.experiment.figures import save_figure

COMPARE = {"<": operator.lt, "<=": operator.le, ">": operator.gt, ">=": operator.ge, "==": operator.eq,
           "!=": operator.ne}
Z95 = 1.959963984540054


def wilson(passed: int, n: int, z: float = Z95) -> tuple[float, float]:
    if n == 0:
        return (0.0, 1.0)
    p = passed / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def t_interval(values: list[float]) -> tuple[float, float, float]:
    """Mean and its 95 % interval (Student's t; scipy is not needed for two-sided 95 %)."""
    n = len(values)
    mean = sum(values) / n
    if n < 2:
        return mean, float("nan"), float("nan")
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    half = _t975(n - 1) * sd / math.sqrt(n)
    return mean, mean - half, mean + half


def _t975(df: int) -> float:
    """Student's t 97.5 % quantile: the table's values to 30, then the normal with Cornish-Fisher's correction."""
    table = [12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145,
             2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048,
             2.045, 2.042]
    if df <= 30:
        return table[df - 1]
    z = Z95
    return z + (z**3 + z) / (4 * df) + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * df * df)


@dataclass
class Judged:
    target: Target
    n: int
    estimate: float
    low: float
    high: float
    met: bool

    def text(self) -> str:
        if self.n == 0:
            return "no runs"
        if self.target.statistic == "mean":
            return f"{'met' if self.met else 'MISSED'}: mean {self.estimate:.4g} [{self.low:.4g}, {self.high:.4g}]"
        passed = round(self.estimate * self.n)
        return (f"{'met' if self.met else 'MISSED'}: {passed}/{self.n} "
                f"({100 * self.estimate:.0f} %, 95 % CI {100 * self.low:.0f}-{100 * self.high:.0f} %)")


def judge(target: Target, values: list) -> Judged:
    """`values`: the metric of every finished run of the cell (None: the run did not measure it, a miss)."""
    test = COMPARE[target.comparison]
    n = len(values)
    if target.statistic == "mean":
        numbers = [float(v) for v in values if v is not None]
        if not numbers:
            return Judged(target, 0, float("nan"), float("nan"), float("nan"), False)
        mean, low, high = t_interval(numbers)
        return Judged(target, len(numbers), mean, low, high, bool(test(mean, target.value)))
    passed = sum(1 for v in values if v is not None and test(v, target.value))
    low, high = wilson(passed, n)
    share = passed / n if n else 0.0
    needed = 1.0 if target.statistic == "all" else target.fraction
    return Judged(target, n, share, low, high, n > 0 and share >= needed - 1e-12)


def _rows(table: pa.Table) -> list[dict]:
    return table.to_pylist()


def factor_columns(table: pa.Table) -> list[str]:
    return [c for c in table.column_names if c.startswith("factor.")]


def cell_table(experiment: Experiment, table: pa.Table) -> str:
    """A row per cell: its factors, runs, failures, and each target judged."""
    rows = _rows(table)
    factors = factor_columns(table)
    cells: dict[str, list[dict]] = {}
    for r in rows:
        cells.setdefault(r["cell"], []).append(r)
    header = [c.removeprefix("factor.") for c in factors] + ["runs", "failed"] + [t.title for t in experiment.targets]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for group in sorted(cells.values(), key=lambda g: [str(g[0].get(c)) for c in factors]):
        ok = [r for r in group if r["status"] == "done"]
        judged = [judge(t, [r.get(f"metric.{t.metric}") for r in ok]).text() for t in experiment.targets]
        cells_text = [str(group[0].get(c)) for c in factors] + [str(len(group)), str(len(group) - len(ok))] + judged
        lines.append("| " + " | ".join(cells_text) + " |")
    return "\n".join(lines) + "\n"


def plots(experiment: Experiment, table: pa.Table, folder: Path) -> list[Path]:
    """A picture per metric: its value in every run against each factor's levels (a panel per factor), the
    median of each level and the metric's targets drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in _rows(table) if r["status"] == "done"]
    factors = factor_columns(table)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    metrics = list(dict.fromkeys([t.metric for t in experiment.targets] + (experiment.metrics or [])))
    for metric in metrics:
        key = f"metric.{metric}"
        if not factors or not any(isinstance(r.get(key), int | float) for r in rows):
            continue
        fig, axes = plt.subplots(1, len(factors), figsize=(3.6 * len(factors), 3.4), squeeze=False)
        for ax, factor in zip(axes[0], factors):
            levels = list(dict.fromkeys(str(r.get(factor)) for r in rows))
            for i, level in enumerate(levels):
                ys = [float(r[key]) for r in rows
                      if str(r.get(factor)) == level and isinstance(r.get(key), int | float)]
                ax.scatter([i + (j % 7 - 3) * 0.03 for j in range(len(ys))], ys, s=8, alpha=0.5)
                if ys:
                    ax.plot([i - 0.3, i + 0.3], [sorted(ys)[len(ys) // 2]] * 2, color="black", linewidth=1)
            for target in experiment.targets:
                if target.metric == metric and not isinstance(target.value, bool):
                    ax.axhline(float(target.value), color="tab:red", linestyle="--", linewidth=0.8)
            ax.set_xticks(range(len(levels)), levels, rotation=30, fontsize=7, ha="right")
            ax.set_title(factor.removeprefix("factor."), fontsize=9)
            ax.grid(alpha=0.3)
        fig.suptitle(f"{metric}: every run by factor (line: median, dashed: target)", fontsize=9)
        written.append(save_figure(fig, folder / f"{metric}.png"))
    return written


def path_plots(experiment: Experiment, table: pa.Table, folder: Path) -> list[Path]:
    """With `paths: FACTOR`: a picture per value of that factor (a scene), every run's robot path in it, a
    colour per combination of the other factors."""
    if experiment.paths is None or "path" not in table.column_names:
        return []
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in _rows(table) if r["status"] == "done" and r.get("path")]
    by = f"factor.{experiment.paths}"
    others = [c for c in factor_columns(table) if c != by]
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for level in dict.fromkeys(str(r.get(by)) for r in rows):
        here = [r for r in rows if str(r.get(by)) == level]
        groups = list(dict.fromkeys(" ".join(str(r.get(c)) for c in others) for r in here))
        colours = plt.get_cmap("tab10")
        fig, ax = plt.subplots(figsize=(7.0, 3.6))
        labelled: set[str] = set()
        for r in here:
            group = " ".join(str(r.get(c)) for c in others)
            xs, ys = json.loads(r["path"])
            ax.plot(xs, ys, color=colours(groups.index(group) % 10), linewidth=0.8, alpha=0.6,
                    label=None if group in labelled else group)
            labelled.add(group)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.grid(alpha=0.3)
        if any(groups):
            ax.legend(fontsize=7, title=" ".join(c.removeprefix("factor.") for c in others), title_fontsize=7)
        ax.set_title(f"{experiment.paths} {level}: every run's path", fontsize=9)
        written.append(save_figure(fig, folder / f"paths-{_file_part(level)}.png"))
    return written


def _file_part(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)


def page(experiment: Experiment, table: pa.Table, pictures: list[Path], folder: Path) -> str:
    rows = table.num_rows
    failed = sum(1 for s in table.column("status").to_pylist() if s != "done") if rows else 0
    out = [f"# Experiment {experiment.name}", "", experiment.doc.strip(), "",
           f"{rows} runs, {failed} failed. Fractions with Wilson's 95 % interval, means with Student's t.", "",
           "## Cells against the targets", "", cell_table(experiment, table)]
    if failed:
        out += ["## Failed runs", "", "| run | message |", "|---|---|"]
        out += [f"| {r['run_id']} | {r['message']} |" for r in _rows(table) if r["status"] != "done"]
        out.append("")
    for name in experiment.summaries:
        out += [f"## {name}", "", summary(name, table), ""]
    if pictures:
        out += ["## Pictures: metrics by factor, paths, summaries", ""]
        out += [f"![{p.stem}]({p.relative_to(folder)})" for p in pictures] + [""]
    return "\n".join(out)


def summary(name: str, table: pa.Table) -> str:
    """A named summary's tables; `NAME:SECTION` the one under its heading `### SECTION`."""
    from hapticop.experiment.summaries import SUMMARIES

    name, _, section = name.partition(":")
    text = SUMMARIES[name](table.to_pylist())
    if not section:
        return text
    for block in text.split("### ")[1:]:
        heading, _, body = block.partition("\n")
        if heading.strip() == section:
            return body.strip("\n") + "\n"
    raise KeyError(f"summary {name} has no section {section}")


def summary_figures(experiment: Experiment, table: pa.Table, folder: Path) -> list[Path]:
    """The pictures of the experiment's named summaries that draw some (`figures.FIGURES`)."""
    from hapticop.experiment.figures import FIGURES

    rows = table.to_pylist()
    return [p for name in experiment.summaries if name in FIGURES for p in FIGURES[name](rows, folder)]


def write_report(experiment: Experiment, table: pa.Table, folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    pictures = (plots(experiment, table, folder / "plots") + path_plots(experiment, table, folder / "plots")
                + summary_figures(experiment, table, folder / "plots"))
    target = folder / "report.md"
    target.write_text(page(experiment, table, pictures, folder))
    return target
