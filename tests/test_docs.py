"""The documentation against the code: generated pages current, every YAML example valid, every
command line one the CLI accepts, every page in the site's navigation, and a README that stays short.

YAML examples (```yaml fences in README.md and docs/) say what they are on their first line:
- `# NAME.yaml...`: a file of the page's own, written into a directory with `hapticop new my_app`'s
  `my_app.yaml` and the files of `systems/` beside it (so it may extend them); a mapping must
  validate without errors, a list is a JSON Patch that must apply to the file named after `for`
  (`# faster.yaml: a JSON Patch for systems/hallway.yaml`) and leave it valid;
- `# excerpt...`: part of a file, checked against the JSON Schema without its required keys;
- anything else: a whole composition, which must validate without errors.
Python examples (```python fences) run, their asserts included.
"""

from __future__ import annotations

import json
import re
import shlex
import shutil
from pathlib import Path

import jsonschema
import pytest
import typer
from ruamel.yaml import YAML

from hapticop.cli import app
from hapticop.cli.docpages import PAGES
from hapticop.cli.main import bare_options  # what main() does to argv before parsing (a bare --record)
from hapticop.cli.new import new
from hapticop.composition.schema import composition_schema
from hapticop.validation import validate_path
from hapticop.validation.patches import apply_patch, load_patch, validate_patched

from .conftest import ROOT

PAGES_WITH_EXAMPLES = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])
FENCE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```", re.MULTILINE | re.DOTALL)


def _fences(page: Path) -> list[tuple[str, int, str]]:
    text = page.read_text()
    return [(match.group(1), text.count("\n", 0, match.start()) + 1, match.group(2)) for match in FENCE.finditer(text)]


def _yaml_examples() -> list:
    return [pytest.param(page, line, body, id=f"{page.relative_to(ROOT)}:{line}")
            for page in PAGES_WITH_EXAMPLES for language, line, body in _fences(page) if language in ("yaml", "yml")]


@pytest.mark.parametrize("name", sorted(PAGES))
def test_generated_pages_are_current(name):
    assert (ROOT / "docs" / name).read_text() == PAGES[name](typer.main.get_command(app)), "run `hapticop docs`"


NAMED = re.compile(r"#\s*([\w.-]+\.ya?ml)\b")


@pytest.fixture(scope="module")
def workspaces(tmp_path_factory):
    """One directory per page, holding the page's named files from before `line` (a later file may extend an
    earlier one). Each example writes its predecessors itself: test workers may split a page's examples."""
    made: dict[Path, Path] = {}

    def workspace(page: Path, line: int) -> Path:
        if page not in made:
            directory = tmp_path_factory.mktemp(page.stem)
            for system in (ROOT / "systems").glob("*.yaml"):
                shutil.copy(system, directory / system.name)
            new("my_app", directory=directory, block=False, force=False)
            made[page] = directory
        for language, at, body in _fences(page):
            named = NAMED.match(body.splitlines()[0]) if body.strip() else None
            if at < line and language in ("yaml", "yml") and named:
                (made[page] / named.group(1)).write_text(body)
        return made[page]

    return workspace


@pytest.mark.parametrize(("page", "line", "body"), _yaml_examples())
def test_yaml_example_is_valid(page, line, body, workspaces):
    first = body.splitlines()[0] if body.strip() else ""
    where = f"{page.relative_to(ROOT)}:{line}"
    named = NAMED.match(first)
    if first.startswith("# excerpt"):
        root = composition_schema()
        partial = {**root, "required": []}
        document = json.loads(json.dumps(YAML(typ="safe").load(body)))  # keys as JSON has them (schedule IDs)
        errors = [error.message for error in jsonschema.Draft202012Validator(partial).iter_errors(document)]
        assert not errors, f"{where}: {errors}"
    elif named:
        directory = workspaces(page, line)
        file = directory / named.group(1)
        file.write_text(body)
        document = YAML(typ="safe").load(body)
        if isinstance(document, list):
            target = re.search(r"\bfor\s+(?:systems/)?([\w.-]+\.ya?ml)", first)
            assert target, f"{where}: a patch example names the file it is for ('... for systems/NAME.yaml')"
            base = directory / target.group(1)
            tree = YAML().load(base.read_text())
            validate_patched(apply_patch(tree, load_patch(body, str(file)), file=str(file)), str(base))
        else:
            report = validate_path(file).report
            assert report.ok, f"{where}:\n" + "\n".join(d.to_text() for d in report.sorted())
    else:
        file = workspaces(page, line) / f"example-{line}.yaml"
        file.write_text(body)
        report = validate_path(file).report
        assert report.ok, f"{where}:\n" + "\n".join(d.to_text() for d in report.sorted())


def _python_examples() -> list:
    return [pytest.param(page, id=str(page.relative_to(ROOT))) for page in PAGES_WITH_EXAMPLES
            if any(language == "python" for language, _, _ in _fences(page))]


@pytest.mark.parametrize("page", _python_examples())
def test_python_examples_run(page):
    """A page's Python examples run in order in one namespace, as a reader would paste them; their asserts hold."""
    namespace: dict = {"__name__": f"docs_{page.stem.replace('-', '_')}"}
    for language, line, body in _fences(page):
        if language == "python":
            exec(compile(body, f"{page.relative_to(ROOT)}:{line}", "exec"), namespace)  # the project's own pages


def _command_lines() -> list:
    """`hapticop ...` lines of the pages' shell examples: indented code blocks and shell fences."""
    found = []
    for page in PAGES_WITH_EXAMPLES:
        shell_fences = {line + offset for language, line, body in _fences(page) if language in ("bash", "sh", "shell")
                        for offset in range(1, body.count("\n") + 1)}
        fenced = {line + offset for _, line, body in _fences(page) for offset in range(1, body.count("\n") + 1)}
        for number, text in enumerate(page.read_text().splitlines(), start=1):
            indented = text.startswith("    ") and number not in fenced
            if (indented or number in shell_fences) and "hapticop " in text:
                found.append(pytest.param(text.strip(), id=f"{page.relative_to(ROOT)}:{number}"))
    return found


def _invocations(line: str) -> list[list[str]]:
    """The hapticop commands of a shell line (`a && hapticop x`, `.venv/bin/hapticop`), comments dropped."""
    words = shlex.split(line, comments=True)
    commands, current = [], []
    for word in [*words, "&&"]:
        if word in ("&&", "||", ";", "|"):
            if current and Path(current[0]).name == "hapticop":
                commands.append(current[1:])
            current = []
        else:
            current.append(word)
    return commands


def _parse(argv: list[str]) -> None:
    """Parse `argv` as `hapticop` would, down to the command's own options, without running anything."""
    argv = bare_options(argv)
    command = typer.main.get_command(app)
    context = command.context_class(command, info_name="hapticop")
    while hasattr(command, "commands") and argv and argv[0] in command.commands:
        name, argv = argv[0], argv[1:]
        command = command.commands[name]
        context = command.context_class(command, info_name=name, parent=context)
    assert not hasattr(command, "commands"), f"{argv[:1]} is not a command of {context.command_path}"
    command.make_context(context.info_name, list(argv), parent=context.parent)


@pytest.mark.parametrize("line", _command_lines())
def test_command_example_parses(line):
    invocations = _invocations(line)
    assert invocations, line
    for argv in invocations:
        _parse(argv)


def test_a_wrong_command_example_would_be_caught():
    with pytest.raises(Exception, match="No such option"):
        _parse(["compose", "systems/wall.yaml", "--durration", "3s"])
    with pytest.raises(AssertionError):
        _parse(["ethercat", "sandbox-typo"])


def test_every_page_is_in_the_site_navigation():
    nav = set(re.findall(r":\s*([\w/.-]+\.md)\s*$", (ROOT / "mkdocs.yml").read_text(), re.MULTILINE))
    pages = {str(page.relative_to(ROOT / "docs")) for page in (ROOT / "docs").rglob("*.md")}
    assert nav <= pages, f"mkdocs.yml names pages that do not exist: {sorted(nav - pages)}"
    assert pages <= nav, f"pages missing from mkdocs.yml's nav: {sorted(pages - nav)}"


def test_the_readme_stays_an_introduction():
    assert len((ROOT / "README.md").read_text().splitlines()) < 250, "move details into docs/"


def test_hapticop_docs_writes_the_pages_and_checks_them(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from hapticop.cli import docpages

    monkeypatch.setattr(docpages, "DOCS", tmp_path)
    runner = CliRunner()
    written = runner.invoke(app, ["docs"])
    assert written.exit_code == 0 and sorted(written.output.split()) == sorted(
        ["wrote"] * len(PAGES) + [f"docs/{name}" for name in PAGES])
    assert runner.invoke(app, ["docs", "--check"]).exit_code == 0
    (tmp_path / "reference" / "cli.md").write_text("stale\n")
    checked = runner.invoke(app, ["docs", "--check"])
    assert checked.exit_code == 1 and "reference/cli.md" in checked.output
    assert (tmp_path / "reference" / "cli.md").read_text() == "stale\n"


def test_the_tutorials_mistakes_print_what_it_shows(tmp_path, monkeypatch):
    """The tutorial's sample of `validate` output is what validate prints for the two mistakes it names."""
    from typer.testing import CliRunner

    page = ROOT / "docs" / "tutorial.md"
    fences = _fences(page)
    files = {re.match(r"#\s*([\w.-]+\.yaml)", body).group(1): body
             for language, _, body in fences if language == "yaml"}
    shown = next(body for language, _, body in fences if language == "text")
    new("my_app", directory=tmp_path, block=False, force=False)
    (tmp_path / "my_wall.yaml").write_text(files["my_wall.yaml"])
    mistaken = files["my_grip.yaml"].replace("max_norm_n: 8.0", "max_norm: 8.0")
    mistaken = mistaken.replace("from: wall.force, to", "from: wal.force, to")
    assert mistaken.count("max_norm:") == 1 and mistaken.count("wal.force") == 1
    (tmp_path / "my_grip.yaml").write_text(mistaken)
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(app, ["validate", "my_grip.yaml"])
    assert result.exit_code == 1
    assert result.output == shown


def test_the_composition_reference_has_every_model_of_the_format():
    """Every model a composition file reaches outside a block's `params` (the hosts, a stream's network
    settings, an emulated link) has a section of its own in docs/reference/composition.md."""
    from hapticop.cli.docpages import FORMAT_MODELS
    from hapticop.composition.schema import composition_schema

    schema = composition_schema()
    reached: set[str] = set()

    def walk(node) -> None:
        if isinstance(node, dict):
            for key, value in node.items():
                if key == "$ref" and value.rsplit("/", 1)[-1] not in reached:
                    reached.add(value.rsplit("/", 1)[-1])
                    walk(schema["$defs"][value.rsplit("/", 1)[-1]])
                elif key != "params":  # a block's parameters: the catalogue's
                    walk(value)
        elif isinstance(node, list):
            for value in node:
                walk(value)

    walk(schema["properties"])
    assert {"Host", "NetworkQoS", "LinkParams"} <= reached
    assert reached <= set(FORMAT_MODELS)
    page = (ROOT / "docs" / "reference" / "composition.md").read_text()
    assert "| `delay_s` | number (s) | `0.0` |" in page and "[NetworkQoS](#networkqos)" in page
