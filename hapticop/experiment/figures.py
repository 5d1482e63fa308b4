"""Named pictures an experiment's report draws beside its named tables (`summaries:` in its file): the hallway
sweep's picture per hallway, which docs/hallway-experiment.md §12 and the README show
(`hapticop experiment report experiments/hallway.yaml --docs` redraws them into docs/figures/)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from hapticop.experiment.summaries import CONTROLS, PROFILES, records

SWEEP_METRICS = (  # (key, label, scale, target band or line)
    ("e_stop_m", "stop error (cm, + early)", 100.0, (-5.0, 10.0)),
    ("side_clearance_min_m", "least side clearance (m)", 1.0, (None, None)),  # the target: per hallway
    ("oscillation_s", "oscillation above 2 cm/s (1 s rms), longest (s)", 1.0, (None, 2.0)),
    ("t_norm", "completion time / T_ref", 1.0, (None, 1.2)),
)
SIDE_MARGIN_M = 0.10
"""The side clearance target: dist1 less this (docs/hallway-experiment.md §6)."""


def _dist1_m(hallway: str) -> float:
    from hapticop.sim import scene_files

    loaded, found = scene_files.load(hallway)
    if loaded is None or loaded.scene is None or loaded.scene.hallway is None:
        raise ValueError(f"{hallway}: not a shipped hallway scene ({'; '.join(d.message for d in found)})")
    return loaded.scene.hallway.dist1_m


def hallway_sweep(rows: list[dict], folder: Path) -> list[Path]:
    """A picture per hallway, `hallway-sweep-H?.png`: each judged metric per run, by operator profile, the
    operator alone beside shared control, with the target drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = records(rows)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for hallway in sorted({r["hallway"] for r in runs}):
        here = [r for r in runs if r["hallway"] == hallway]
        fig, axes = plt.subplots(1, len(SWEEP_METRICS), figsize=(4.2 * len(SWEEP_METRICS), 3.6))
        for ax, (key, label, scale, (low, high)) in zip(axes, SWEEP_METRICS):
            for offset, control, colour in zip((-0.15, 0.15), CONTROLS, ("tab:blue", "tab:orange")):
                xs, ys = [], []
                for i, profile in enumerate(PROFILES):
                    for r in here:
                        value = r["metrics"].get(key)
                        if r["profile"] == profile and r["control"] == control and value is not None:
                            xs.append(i + offset)
                            ys.append(scale * value)
                ax.scatter(xs, ys, s=14, alpha=0.7, color=colour, label=control)
            if key == "side_clearance_min_m":
                low = _dist1_m(hallway) - SIDE_MARGIN_M
            for bound in (low, high):
                if bound is not None:
                    ax.axhline(bound, color="tab:red", linewidth=0.8, linestyle="--")
            ax.set_xticks(range(len(PROFILES)), PROFILES, rotation=30, fontsize=8)
            ax.set_title(label, fontsize=9)
            ax.grid(alpha=0.3)
        axes[0].legend(fontsize=8)
        fig.suptitle(f"hallway {hallway}: every run (dashed: the target)", fontsize=10)
        written.append(save_figure(fig, folder / f"hallway-sweep-{hallway}.png", dpi=90))
    return written


def save_figure(fig, target: Path, dpi: int = 80) -> Path:
    """Lay the figure out, write it to `target` as PNG and free it (pyplot keeps every open figure)."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(target, dpi=dpi)
    plt.close(fig)
    return target


FIGURES: dict[str, Callable[[list[dict], Path], list[Path]]] = {"hallway_sweep": hallway_sweep}
"""The pictures of a named summary, drawn with its table."""
