import json

import pytest

from multiarm_pin.exceptions import StudyError
from multiarm_pin.study.spec import load_study
from multiarm_pin.study.store import ResultsFolder, read_table, write_atomic
from tests.study.helpers import tiny_grasp_study


def test_write_atomic_replaces_whole_files_and_leaves_no_temporaries(tmp_path):
    p = tmp_path / "a" / "f.json"
    write_atomic(p, "one")
    write_atomic(p, "two")
    assert p.read_text() == "two" and [x.name for x in p.parent.iterdir()] == ["f.json"]


def test_finished_rows_need_the_current_key_and_a_real_status(tmp_path):
    spec = load_study(tiny_grasp_study(tmp_path, samples=2))
    cases = spec.cases()
    folder = ResultsFolder(tmp_path / "out")
    assert folder.prepare(spec, cases, resume=False) == {}
    base = {"index": 0, "status": "ok", "error": "", "margin": float("nan")}
    folder.write_case({**base, "case_id": cases[0].case_id, "key": cases[0].key}, {"s": 1})
    folder.write_case({**base, "case_id": cases[1].case_id, "key": "stale"}, None)
    folder.write_case({**base, "case_id": cases[2].case_id, "key": cases[2].key,
                       "status": "lost"}, None)
    done = folder.finished(cases)
    assert list(done) == [cases[0].case_id]
    row = json.loads((folder.cases_dir / cases[0].case_id / "row.json").read_text())
    assert row["margin"] is None  # NaN stored as null (strict JSON)
    folder.write_table(done.values())
    assert read_table(folder.path).column("case_id").to_pylist() == [cases[0].case_id]
    # the same folder accepts the same study again, and --resume now
    assert list(folder.prepare(spec, cases, resume=True)) == [cases[0].case_id]


def test_out_folder_that_is_not_a_study_is_refused(tmp_path):
    spec = load_study(tiny_grasp_study(tmp_path, samples=2))
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "x.txt").write_text("mine")
    with pytest.raises(StudyError, match="not empty"):
        ResultsFolder(busy).prepare(spec, spec.cases(), resume=False)
    with pytest.raises(StudyError, match="cannot read the results table"):
        read_table(tmp_path / "nothing")


def test_a_study_refuses_a_folder_another_run_or_study_is_writing(tmp_path):
    # the same lock as `multiarm-pin run`: held here as another process would hold it
    from multiarm_pin.app.results_io import folder_lock
    from multiarm_pin.exceptions import OutputError
    from multiarm_pin.study import Study

    study = Study(tiny_grasp_study(tmp_path, samples=2))
    out = tmp_path / "out"
    other = folder_lock(out, tmp_path / "other_study.yaml")
    other.acquire()
    try:
        with pytest.raises(OutputError, match=r"another run is writing into this folder "
                                              r"\(pid \d+, scenario .*other_study\.yaml"):
            study.run_loop(out=out)
        assert not out.exists()  # nothing written
    finally:
        other.release()
    table = study.run_loop(out=out)  # free again: runs, and releases its lock
    assert table.num_rows == len(study.cases)
    assert not (tmp_path / ".out.lock").exists()
