"""The study lifecycle (clusterdyn.studies.base): registry, refusal before any folder, the cache,
the shared tail (JSON, file list, printed text)."""

import json

import pytest

from clusterdyn.errors import InputError
from clusterdyn.scenes.base import Param, Quantity, SceneResult
from clusterdyn.studies import STUDIES, get_study, study_names, study_params, study_summary
from clusterdyn.studies.base import Report, Study, register_study
from clusterdyn.studies.common import ListParam, StudyPoint, write_csv

CALLS = []


def _square(v, out=None, progress=False):
    CALLS.append(v["x"])
    return SceneResult("square", {"y": Quantity(v["x"] ** 2, "")}, 0.0)


SQUARE = StudyPoint("square", "x squared", [Param("x", 1.0, "a number")], _square)


class SquaresStudy(Study):
    name = "test-squares"
    summary = "squares of a list (a test of the lifecycle)"
    params = [ListParam("xs", (1.0, 2.0), "numbers"), Param("reuse", True, "read back", kind="bool")]
    json_name = "squares.json"

    def tag(self, run):
        return f"{len(run.v['xs'])}"

    def prepare(self, run):
        if any(x < 0 for x in run.v["xs"]):
            raise InputError("xs", run.v["xs"], "numbers >= 0")

    def plan(self, run):
        return [{"x": x} for x in run.v["xs"]]

    def collect(self, run, plan):
        return [run.run_scene(SQUARE, ov)[0].quantities["y"].value for ov in plan]

    def report(self, run, ys):
        rows = [{"x": x, "y": y} for x, y in zip(run.v["xs"], ys)]
        return Report({"study": self.name, "rows": rows}, [f"{len(rows)} squares"],
                      [write_csv(run.folder / "squares.csv", rows)])


@pytest.fixture
def squares():
    study = register_study(SquaresStudy())
    yield study
    STUDIES.pop(study.name)


def test_every_study_is_registered_with_its_parameters():
    assert study_names()[:3] == ["hugoniot", "convergence", "stability"]
    for name in study_names():
        study = get_study(name)
        assert isinstance(study, Study) and study.name == name and study_summary(name)
        assert study_params(name) and all(isinstance(p, Param) for p in study_params(name))
    with pytest.raises(InputError, match="study='nosuch'"):
        get_study("nosuch")


def test_lifecycle_refuses_before_any_folder_then_runs_caches_and_reports(squares, tmp_path, capsys):
    assert get_study("test-squares") is squares
    out = tmp_path / "out"
    with pytest.raises(InputError, match="xs="):
        squares({"xs": "1,-2"}, out=out, progress=False)
    with pytest.raises(InputError, match="--set="):
        squares({"colour": "red"}, out=out, progress=False)
    assert not out.exists()
    CALLS.clear()
    res = squares({"xs": "1,3"}, out=out, progress=False, quiet=False)
    assert [r["y"] for r in res["rows"]] == [1.0, 9.0] and CALLS == [1.0, 3.0]
    assert res["files"] == [str(out / "squares.csv"), str(out / "squares.json")]
    saved = json.loads((out / "squares.json").read_text())
    assert saved["rows"] == res["rows"] and saved["wall_time_s"] == res["wall_time_s"]
    assert capsys.readouterr().out.startswith("2 squares\n\nwrote ")
    assert len(list((out / "runs").iterdir())) == 2            # one cached folder per run
    # again with one more number: the two cached runs are read back, one is run
    res = squares({"xs": "1,3,4"}, out=out, progress=False)
    assert [r["y"] for r in res["rows"]] == [1.0, 9.0, 16.0] and CALLS == [1.0, 3.0, 4.0]
    assert capsys.readouterr().out == ""                       # progress=False: quiet
    # reuse=false runs everything again
    squares({"xs": "1", "reuse": "false"}, out=out, progress=False)
    assert CALLS[-1] == 1.0 and len(CALLS) == 4
