"""YAML-level failures get one clean, located diagnostic; never an exception."""

from hapticop.composition.yamlsource import MAX_FILE_BYTES, locate, parse_text
from hapticop.validation import validate_path, validate_text


def only(report):
    assert len(report.diagnostics) == 1, report.diagnostics
    return report.diagnostics[0]


def test_malformed_yaml_is_located():
    d = only(validate_text("version: 1\nthreads:\n  main: [1, 2\n", "f.yaml").report)
    assert d.rule == "yaml-syntax" and d.file == "f.yaml" and d.line >= 3


def test_duplicate_key_is_located():
    text = "version: 1\nthreads: {}\nactivities: {}\nthreads: {}\n"
    d = only(validate_text(text, "dup.yaml").report)
    assert d.rule == "duplicate-key" and d.line == 4 and "threads" in d.message


def test_empty_file():
    for text in ("", "   \n# only a comment\n"):
        d = only(validate_text(text, "empty.yaml").report)
        assert d.rule == "empty-file" and d.line == 1


def test_top_level_must_be_a_mapping():
    for text, kind in (("- a\n- b\n", "list"), ("just text\n", "string"), ("42\n", "number")):
        d = only(validate_text(text).report)
        assert d.rule == "top-level-type" and kind in d.message


def test_large_file_refused_cleanly(tmp_path):
    big = tmp_path / "big.yaml"
    line = "# " + "x" * 98 + "\n"
    big.write_text("version: 1\n" + line * (10 * 1024 * 1024 // len(line)))
    d = only(validate_path(big).report)
    assert d.rule == "file-too-large" and "10.5 MB" in d.message
    d = only(validate_text("a: 1\n" + line * (MAX_FILE_BYTES // len(line) + 1)).report)
    assert d.rule == "file-too-large"


def test_missing_and_binary_files(tmp_path):
    assert only(validate_path(tmp_path / "nope.yaml").report).rule == "file-unreadable"
    binary = tmp_path / "b.yaml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    assert only(validate_path(binary).report).rule == "file-encoding"


def test_recursive_anchor_refused():
    d = only(validate_text("&x {a: *x}\n").report)
    assert d.rule == "yaml-recursive"


def test_locate_keys_values_and_items():
    source = parse_text("a:\n  b: 3\n  c:\n    - x\n    - y\n")
    assert locate(source.tree, ("a", "b")) == (2, 6)
    assert locate(source.tree, ("a", "b"), key=True) == (2, 3)
    assert locate(source.tree, ("a", "c", 1)) == (5, 7)
    # Segments that are not in the tree (union tags, missing fields) are skipped.
    assert locate(source.tree, ("a", "function-after[x]", "b")) == (2, 6)
    assert locate(source.tree, ("a", "missing")) == (1, 1)
