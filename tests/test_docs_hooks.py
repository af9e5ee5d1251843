"""docs/hooks.py without a site build: the published tables split by columns keep every cell."""

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "hooks.py")
hooks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(hooks)


def _cells_by_key(markdown: str, key: list[str]) -> set[tuple]:
    """(row key..., column, value) of every cell of the Markdown tables whose header starts with ``key``."""
    cells, header = set(), None
    for line in markdown.splitlines() + [""]:
        if not line.startswith("|"):
            header = None
        elif header is None:
            header = hooks._cells(line)
        elif header[:len(key)] == key and not line.startswith("|---"):
            row = hooks._cells(line)
            cells |= {(*row[:len(key)], h, v) for h, v in zip(header, row)}
    return cells


def test_a_split_table_keeps_every_cell_under_its_header():
    text = "before\n\n| key | a | b \\| c |\n|---|---|---|\n| x | 1 | 2 |\n| y | 3 | 4 |\n\nafter"
    split = hooks._split_tables(text, (("key", "b \\| c"), ("key", "a")), "example")
    assert split.startswith("before\n\n| key | b \\| c |\n|---|---|\n| x | 2 |\n| y | 4 |\n\n| key | a |\n")
    assert split.endswith("| y | 3 |\n\nafter")


def test_a_split_that_no_longer_matches_its_table_stops_the_build():
    text = "| key | a | b |\n|---|---|---|\n| x | 1 | 2 |"
    with pytest.raises(ValueError, match=r"SPLITS\['example'\]: no table .* has the columns \['a', 'key'\]"):
        hooks._split_tables(text, (("key", "a"),), "example")        # column b would fall off the page


@pytest.mark.parametrize("name", sorted(hooks.SPLITS))
def test_every_published_cell_reaches_the_page(name):
    """The split tables of a benchmark hold each (row key, column, value) of its stored table."""
    groups = hooks.SPLITS[name]
    key = [c for c in groups[0] if all(c in g for g in groups)]
    data = json.loads((ROOT / "docs" / "validation" / "data" / f"{name}.json").read_text())
    stored = _cells_by_key(data["markdown"], key)
    shown = _cells_by_key(hooks._published_markdown(data, name), key)
    assert len(stored) >= len({c for g in groups for c in g}) and stored <= shown
