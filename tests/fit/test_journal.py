"""The fit's journal: generations written whole are read back; a last line cut short by a
crash is left out (and the file mended), a damaged line before the end or another fit's
journal starts the fit afresh, with a warning."""
from __future__ import annotations

import pytest

from lumitrace.errors import LumitraceWarning
from lumitrace.fit.journal import Journal, pack_state, unpack_state


def _generation(n: int) -> dict:
    return {"kind": "generation", "generation": n, "state": pack_state({"n": n})}


def test_generations_come_back_and_a_cut_last_line_is_left_out(tmp_path):
    j = Journal(tmp_path, "key-a")
    assert j.load() == []
    for n in range(3):
        j.append(_generation(n))
    with open(j.path, "a") as fh:
        fh.write('{"kind":"generation","generation":3,"sta')  # a crash mid-line
    got = Journal(tmp_path, "key-a").load()
    assert [g["generation"] for g in got] == [0, 1, 2]
    assert unpack_state(got[-1]["state"]) == {"n": 2}
    assert j.path.read_text().endswith("\n")  # mended: the next line starts on its own
    j.append(_generation(3))
    assert [g["generation"] for g in Journal(tmp_path, "key-a").load()] == [0, 1, 2, 3]


def test_another_fits_journal_or_a_damaged_one_starts_afresh(tmp_path):
    j = Journal(tmp_path, "key-a")
    j.load()
    j.append(_generation(0))
    with pytest.warns(LumitraceWarning, match="journal of another fit"):
        assert Journal(tmp_path, "key-b").load() == []
    j = Journal(tmp_path, "key-b")
    j.append(_generation(0))
    j.append(_generation(1))
    lines = j.path.read_text().splitlines()
    lines[1] = lines[1][:10]
    j.path.write_text("\n".join(lines) + "\n")
    with pytest.warns(LumitraceWarning, match="damaged"):
        assert Journal(tmp_path, "key-b").load() == []
    assert Journal(tmp_path, "key-b").load(fresh=True) == []
