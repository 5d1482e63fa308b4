"""systems/push_box.yaml for several masses and frictions of its box: the force the hand feels against them.

Each cell is the shipped composition run under the virtual clock through `hapticop compose`, varied by YAML
alone: a copy of scenes/push_box.yaml with the box's mass and friction changed, and a two-line layer that
extends push_box.yaml and names that scene. The felt force is the mean of the `felt_push` stream's z (towards
the operator) from the first contact to the last; the box's travel comes from `box_pose`.

    python bench/push_box.py [--out docs/figures/push_box.png]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from hapticop.recording.reading import series_of

SYSTEMS = Path(__file__).resolve().parent.parent / "systems"
MASSES_KG = (5.0, 15.0, 30.0)
FRICTIONS = (0.3, 0.6)
BOX = "mass_kg: 10.0, material: wood, friction: 0.5}"


def felt(folder: Path, mass_kg: float, friction: float) -> tuple[float, float]:
    """The mean felt force (N) while the robot touches the box, and how far the box went (m)."""
    tag = f"m{mass_kg:g}_f{friction:g}".replace(".", "_")
    scene = (SYSTEMS / "scenes" / "push_box.yaml").read_text()
    assert BOX in scene, "scenes/push_box.yaml's box is not what this bench changes"
    (folder / f"{tag}.scene.yaml").write_text(scene.replace(BOX, f"mass_kg: {mass_kg}, material: wood, "
                                                                 f"friction: {friction}}}"))
    layer = folder / f"{tag}.yaml"
    layer.write_text(f"extends: {SYSTEMS / 'push_box.yaml'}\nname: {tag}\n"
                     f"activities: {{world: {{params: {{scene: {folder / (tag + '.scene.yaml')}}}}}}}\n")
    record = folder / f"{tag}.mcap"
    subprocess.run([sys.executable, "-m", "hapticop.cli", "compose", str(layer), "--clock", "virtual", "--record",
                    str(record)], check=True, stdout=subprocess.DEVNULL, cwd=folder)
    return summarise(record)


def summarise(record: Path) -> tuple[float, float]:
    """Mean felt force (N, towards the operator) from the first contact to the last, and the box's travel (m)."""
    streams = series_of(record, ["felt_push", "box_pose"])
    z = streams["felt_push"].values[:, 2]
    touching = np.flatnonzero(z > 0.0)
    x = streams["box_pose"].values[:, 0, 0]
    if touching.size == 0:
        return 0.0, float(x[-1] - x[0])
    return float(z[touching[0]:touching[-1] + 1].mean()), float(x[-1] - x[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/figures/push_box.png"))
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for friction in FRICTIONS:
            for mass in MASSES_KG:
                force, travel = felt(Path(tmp), mass, friction)
                rows.append((friction, mass, force, travel))
                print(f"friction {friction:.1f}  mass {mass:5.1f} kg  felt {force:.3f} N  box moved {travel:.2f} m",
                      flush=True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for friction in FRICTIONS:
        cells = [(m, f) for mu, m, f, _ in rows if mu == friction]
        ax.plot(*zip(*cells, strict=True), "o-", label=f"box friction {friction}")
    ax.set_xlabel("box mass (kg)")
    ax.set_ylabel("mean force felt on the handle (N)")
    ax.set_title("systems/push_box.yaml: feel how heavy")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
