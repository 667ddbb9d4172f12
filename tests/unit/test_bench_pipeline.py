"""The pipeline benchmark's reading of a snakemake log and of the run jobs' benchmark files."""

from __future__ import annotations

import pytest

from benchmarks.bench_pipeline import group, main, parse_log, projection, report, run_times

LOG = """\
Select jobs to execute...
Execute 2 jobs...
[Wed Dec  2 13:00:58 2026]
localrule check_case:
    input: config/cases/chain3.yaml
    jobid: 43
    wildcards: case=chain3
    resources: tmpdir=/tmp
[Wed Dec  2 13:00:59 2026]
rule run_case_order:
    jobid: 68
    wildcards: case=chain3, level=0, surface=facets, order=2
    priority: 10
[Wed Dec  2 13:01:02 2026]
Finished jobid: 43 (Rule: check_case)
[Wed Dec  2 13:03:08 2026]
Finished jobid: 68 (Rule: run_case_order)
[Wed Dec  2 13:03:10 2026]
localrule all:
    jobid: 0
    reason: Input files updated by another job
[Wed Dec  2 13:03:10 2026]
Finished jobid: 0 (Rule: all)
Complete log(s): /somewhere/.snakemake/log/x.snakemake.log
Elapsed time: 0:02:12.500000
"""


def test_the_log_gives_each_jobs_start_and_finish_and_the_wall_time():
    elapsed, jobs = parse_log(LOG)
    assert elapsed == pytest.approx(132.5)
    assert [(j.jobid, j.rule, j.start, j.seconds) for j in jobs] == \
        [(43, "check_case", 0.0, 4.0), (68, "run_case_order", 1.0, 129.0), (0, "all", 132.0, 0.0)]
    assert jobs[1].wildcards == "case=chain3, level=0, surface=facets, order=2"


def test_a_log_cut_short_has_no_wall_time_and_unfinished_jobs():
    elapsed, jobs = parse_log(LOG.split("[Wed Dec  2 13:03:08 2026]")[0])
    assert elapsed is None
    assert [j.seconds for j in jobs] == [4.0, None]


def test_runs_are_grouped_by_order_and_level():
    assert group("chain3/L0_facets_o2") == "order 2"
    assert group("planar/L3_nurbs_fit") == "levels 2+"
    assert group("chain2_steel/L2_nurbs_fe") == "levels 2+"
    assert group("chain2_rubber/L1_facets") == "rest"


def test_the_report_adds_the_runs_and_the_other_jobs(tmp_path):
    runs = tmp_path / "results" / "benchmarks" / "runs" / "chain3"
    runs.mkdir(parents=True)
    header = "s\th:m:s\tmax_rss\n"
    (runs / "L0_facets_o2.tsv").write_text(header + "129.25\t0:02:09\t1000\n")
    (runs / "L2_facets.tsv").write_text(header + "40.5\t0:00:40\t900\n")
    assert run_times(runs.parent) == {"chain3/L0_facets_o2": 129.25, "chain3/L2_facets": 40.5}
    log = tmp_path / "x.snakemake.log"
    log.write_text(LOG)
    out = report(tmp_path, log, cores=2)
    # the run job's own file, not the log's second-resolution span, plus check_case and all
    assert out["job_s"] == pytest.approx(129.25 + 40.5 + 4.0)
    assert out["groups_s"] == {"order 2": 129.25, "levels 2+": 40.5}
    assert out["busy"] == pytest.approx(out["job_s"] / (2 * 132.5))
    # at the same use of the cores, a wall time equal to this run's allows exactly its job time,
    # and this work then fits where the probe takes what it took here
    same = projection(out, probe_s=10.0, target_min=132.5 / 60.0)
    assert same["allowed_job_s"] == pytest.approx(out["job_s"])
    assert same["probe_at_target_s"] == pytest.approx(10.0)
    half = projection(out, probe_s=10.0, target_min=132.5 / 120.0)
    assert half["probe_at_target_s"] == pytest.approx(5.0)
    assert half["job_probes"] == pytest.approx(out["job_s"] / 10.0)


def test_an_unfinished_run_is_an_error_naming_the_log(tmp_path, capsys, monkeypatch):
    import benchmarks.bench_pipeline as bench

    def no_probe():
        raise AssertionError("the probe ran before the log was checked")
    monkeypatch.setattr(bench, "probe", no_probe)
    (tmp_path / ".snakemake" / "log").mkdir(parents=True)
    log = tmp_path / ".snakemake" / "log" / "x.snakemake.log"
    log.write_text(LOG.split("Complete log(s)")[0])
    assert main(["--root", str(tmp_path), "--probe"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no elapsed time" in err[0] and str(log) in err[0]
