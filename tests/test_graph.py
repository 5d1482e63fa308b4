"""`hapticop graph` as a user reads it: one view at a time, a bounded size, labels once, the file
where the user is, and a picture even without graphviz."""

import re
import sys
import xml.etree.ElementTree as ET

import pytest
from typer.testing import CliRunner

from hapticop.cli import app
from hapticop.cli import render as render_module
from hapticop.cli.render import MAX_SIZE_IN, drawing, to_dot
from hapticop.cli.svg import MAX_WIDTH
from hapticop.validation import validate_path

from .conftest import SYSTEMS

runner = CliRunner()
HALLWAY = SYSTEMS / "hallway.yaml"
VIEWS = ("dataflow", "nets", "mediator", "all")


@pytest.fixture(scope="module")
def hallway():
    return validate_path(HALLWAY).graph


@pytest.fixture
def without_graphviz(monkeypatch):
    """Neither the dot program nor the pygraphviz wheel: the base install."""
    monkeypatch.setattr(render_module.shutil, "which", lambda name: None)
    monkeypatch.setitem(sys.modules, "pygraphviz", None)  # import fails as if not installed
    assert render_module.renderer() == "layered"


def _svg_size(path) -> tuple[float, float]:
    root = ET.parse(path).getroot()
    return tuple(float(re.match(r"[\d.]+", root.get(side)).group()) for side in ("width", "height"))


def test_each_view_shows_only_its_part(hallway):
    dataflow = to_dot(drawing(hallway, "dataflow"))
    assert '"activity:haptic"' in dataflow and "place:" not in dataflow and "flag:" not in dataflow
    nets = to_dot(drawing(hallway, "nets"))
    assert "activity:" not in nets
    assert all(f"cluster_net:{name}" in nets for name in ("mediator", "thread_lcsm", "thread_scheduler"))
    one = to_dot(drawing(hallway, "thread_scheduler"))
    assert "cluster_net:thread_scheduler" in one and "cluster_net:mediator" not in one
    assert '"flag:flags.select_schedules"' in one  # the flags its flag maps bind come with it
    everything = to_dot(drawing(hallway, "all"))
    assert '"activity:haptic"' in everything and "cluster_net:mediator" in everything


def test_a_stream_is_labelled_once(hallway):
    """A stream with two readers fans out from one junction: its name is written once."""
    comp = hallway.loaded.composition
    dataflow = to_dot(drawing(hallway, "dataflow"))
    for name in comp.streams:
        assert dataflow.count(f'label="{name}') == 1, name
    assert '"activity:haptic" -> "stream:velocity_setpoint" [label="velocity_setpoint", arrowhead=none' in dataflow
    assert '"stream:velocity_setpoint" -> "activity:ropod"' in dataflow
    assert '"stream:velocity_setpoint" -> "activity:world"' in dataflow


@pytest.mark.parametrize("view", VIEWS)
def test_each_view_renders_within_a_screen(view, tmp_path):
    target = tmp_path / f"{view}.svg"
    result = runner.invoke(app, ["graph", str(HALLWAY), "--view", view, "-o", str(target)])
    assert result.exit_code == 0, result.output
    width, height = _svg_size(target)  # graphviz writes points
    assert 0 < width <= MAX_SIZE_IN * 72 and 0 < height <= MAX_SIZE_IN * 72


@pytest.mark.parametrize("view", VIEWS)
def test_without_graphviz_the_svg_comes_from_the_layered_layout(view, tmp_path, without_graphviz):
    target = tmp_path / f"{view}.svg"
    result = runner.invoke(app, ["graph", str(HALLWAY), "--view", view, "-o", str(target)])
    assert result.exit_code == 0, result.output
    assert "without graphviz" in result.output
    width, height = _svg_size(target)
    assert 0 < width <= MAX_WIDTH and height > 0
    text = target.read_text()
    assert "haptic_controller" in text if view in ("dataflow", "all") else "START" in text


def test_without_graphviz_a_png_says_what_to_install(tmp_path, without_graphviz):
    result = runner.invoke(app, ["graph", str(HALLWAY), "--format", "png", "-o", str(tmp_path / "x.png")])
    assert result.exit_code == 1
    assert "apt-get install graphviz" in result.output and "SVG (the default)" in result.output
    assert "Traceback" not in result.output


def test_the_picture_lands_where_the_user_is(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    before = set(SYSTEMS.iterdir())
    result = runner.invoke(app, ["graph", str(HALLWAY), "--view", "nets"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "hallway-nets.svg").is_file()
    assert f"wrote {tmp_path / 'hallway-nets.svg'}" in result.output
    assert set(SYSTEMS.iterdir()) == before  # never beside the shipped compositions
    elsewhere = tmp_path / "out" / "picture.dot"
    elsewhere.parent.mkdir()
    assert runner.invoke(app, ["graph", str(HALLWAY), "--format", "dot", "-o", str(elsewhere)]).exit_code == 0
    assert elsewhere.read_text().startswith('digraph "hallway (dataflow)"')


def test_an_unknown_view_lists_the_views():
    result = runner.invoke(app, ["graph", str(HALLWAY), "--view", "medaitor"])
    assert result.exit_code == 2
    assert "no view 'medaitor': choose one of dataflow, nets, all, mediator" in result.output


# -- the layout without graphviz: legible on the shipped systems ---------------------------------

# Edge crossings the layered layout may draw at most (counted with `crossings`): what it drew before
# it packed parts, chose its direction and kept its best ordering, and, for a composition changed
# since, what it drew once the change came (the hallway's scene world feeds its contact force back
# to the plant: one stream against the flow, 21 -> 38 crossings in the dataflow; the scan rendered by
# scan_field between the LIDAR and the haptic controller: one layer more, which the Falcon's two
# streams to the controller now cross, 38 -> 45, the picture checked by eye). A change to the
# layout may not draw more.
CROSSINGS_BEFORE = {
    ("hallway", "dataflow"): 45, ("hallway", "nets"): 184, ("hallway", "all"): 248,
    ("teleop", "dataflow"): 50, ("teleop", "nets"): 185, ("teleop", "all"): 284,
    ("teleop_sim", "dataflow"): 108, ("teleop_sim", "nets"): 184, ("teleop_sim", "all"): 328,
    ("wall", "dataflow"): 10, ("wall", "nets"): 1, ("wall", "all"): 11,
}


@pytest.fixture(scope="module")
def laid_out():
    from hapticop.cli.layered import layout

    graphs = {name: validate_path(SYSTEMS / f"{name}.yaml").graph for name, _ in CROSSINGS_BEFORE}
    return {(name, view): (drawing(graphs[name], view), layout(drawing(graphs[name], view)))
            for name, view in CROSSINGS_BEFORE}


@pytest.mark.parametrize(("name", "view"), list(CROSSINGS_BEFORE))
def test_the_layout_without_graphviz_is_legible(laid_out, name, view):
    from hapticop.cli.layered import crossings
    from hapticop.cli.svg import to_svg

    picture, laid = laid_out[(name, view)]
    # no two boxes overlap: nodes, and the edges' labels laid out as boxes
    shown = [(nid, box) for nid, box in laid.boxes.items() if nid in picture.nodes or box.height > 4]
    shown.sort(key=lambda item: item[1].x - item[1].width / 2)
    for i, (first, a) in enumerate(shown):
        for second, b in shown[i + 1:]:
            if b.x - b.width / 2 >= a.x + a.width / 2:
                break  # sorted by left edge: none further can overlap `a`
            assert abs(a.y - b.y) >= (a.height + b.height) / 2, (first, second)
    # the picture about a screen's shape, not a strip (the dataflow was 2634 x 428 px)
    svg = ET.fromstring(to_svg(picture))
    width, height = float(svg.get("width")), float(svg.get("height"))
    assert 1 / 3 <= width / height <= 3, (width, height)
    assert crossings(laid) <= CROSSINGS_BEFORE[(name, view)]
