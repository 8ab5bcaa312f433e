"""`mrguide cycles report`: a production run's figures recomputed from its run log, and its slim copy."""

from __future__ import annotations

import gc
import gzip
import json
import os

import pytest

from mrguide.cli import main
from mrguide.deploy.cycle_report import (
    LATER_ANATOMY,
    WARMUP_CYCLES,
    anatomy_table,
    cycle_figures,
    miss_anatomy,
    rss_growth_after_warmup,
)
from mrguide.deploy.host_stats import MISS_ANATOMY, FullCollections, HostCounters, cpu_steal_s, pressure_stall_s
from mrguide.deploy.runlog import RunLog, read_log, slim_records


def write_run(path, segments=True):
    """Three cycles: placed at once; placed after a drop; an alarm after two no-grasps (one retried)."""
    with RunLog(path, {"command": "deploy", "cycles": 3}) as log:
        # the attempts of cycles 0, 1, 1, 2, 2
        for episode, outcome in enumerate(["success", "dropped", "success", "no_grasp", "no_grasp"]):
            log.write("episode_start", episode=episode)
            log.write("decision", episode=episode, t=0, setpoints=[[0.0] * 6] * 25)
            log.write("episode_end", episode=episode, outcome=outcome)
        log.write("cycle_end", cycle=0, placed=True, outcomes=["success"], retries=[], alarm=None, cycle_s=4.0)
        log.write("retry", cycle=1, attempt=1, cause="dropped")
        log.write(
            "cycle_end",
            cycle=1,
            placed=True,
            outcomes=["dropped", "success"],
            retries=["dropped"],
            alarm=None,
            cycle_s=8.0,
        )
        log.write(
            "cycle_end",
            cycle=2,
            placed=False,
            outcomes=["no_grasp"] * 2,
            retries=["no_grasp"],
            alarm="2 failed attempts",
            cycle_s=9.0,
        )
        if segments:
            log.write("cycles_end", wall_s=36.0, missed_cycles=2, underruns=1, rss_growth_mb=3.5)


def write_placed_cycle(log: RunLog, cycle: int, **counters: object) -> None:
    """A cycle_end record of a part placed at the first attempt in 4 s, with the driver and host counters given."""
    log.write(
        "cycle_end", cycle=cycle, placed=True, outcomes=["success"], retries=[], alarm=None, cycle_s=4.0, **counters
    )


def test_the_figures_come_from_the_cycle_records(tmp_path):
    write_run(tmp_path / "run.jsonl")
    f = cycle_figures(read_log(tmp_path / "run.jsonl"))
    assert (f["cycles"], f["placed"], f["placed_first_attempt"], f["alarms"]) == (3, 2, 1, 1)
    assert f["retries"] == {"dropped": 1, "no_grasp": 1}
    assert f["cycle_s_median"] == pytest.approx(6.0) and f["parts_per_hour"] == pytest.approx(200.0)
    assert (f["missed_cycles"], f["underruns"], f["rss_growth_mb"]) == (2, 1, 3.5)
    assert f["cycles_with_missed"] is None  # the cycles do not record their own count (logs before it did)
    assert f["cut"] == 0  # the unplaced cycle has its alarm


def test_a_part_seen_at_its_goal_after_a_failed_attempt_is_placed_but_not_at_the_first_attempt(tmp_path, capsys):
    with RunLog(tmp_path / "run.jsonl", {"command": "deploy"}) as log:
        write_placed_cycle(log, 0)
        log.write("placed_on_check", cycle=1, part=[0.5, 0.2, 0.025], goal=[0.5, 0.21, 0.025])
        log.write("cycle_end", cycle=1, placed=True, outcomes=["timeout"], retries=[], alarm=None, cycle_s=7.0)
        log.write("cycles_end", wall_s=11.0, missed_cycles=0, underruns=0, rss_growth_mb=0.0)
    f = cycle_figures(read_log(tmp_path / "run.jsonl"))
    assert (f["placed"], f["placed_first_attempt"], f["placed_on_check"]) == (2, 1, 1)
    assert main(["cycles", "report", str(tmp_path / "run.jsonl"), "--out", str(tmp_path / "out")]) == 0
    assert "2 / 2 (1 seen at the goal after a failed attempt)" in capsys.readouterr().out


def test_a_session_still_running_adds_no_parts_to_the_hourly_rate(tmp_path):
    """Resumed with `--resume` and read while the new session runs: its cycles count as cycles, but the parts per
    hour are the ended session's (its wall time is all the log has), not every part over that session's time."""
    write_run(tmp_path / "live.jsonl")
    with RunLog(tmp_path / "live.jsonl", {"command": "deploy", "cycles": 100}) as log:
        for cycle in range(3, 40):
            write_placed_cycle(log, cycle)
    f = cycle_figures(read_log(tmp_path / "live.jsonl"))
    assert (f["cycles"], f["placed"]) == (40, 39)
    assert f["parts_per_hour"] == pytest.approx(200.0)  # 2 parts in the first session's 36 s


def test_a_cycle_a_stop_cut_short_is_counted_apart_from_the_alarms(tmp_path, capsys):
    """A run stopped in a cycle (the watchdog, Ctrl-C twice) ends it unplaced without an alarm; `--resume` goes on
    with the next one. The table says how many of the unplaced cycles were cut so."""
    log_path = tmp_path / "cut.jsonl"
    with RunLog(log_path, {"command": "deploy", "cycles": 3}) as log:
        write_placed_cycle(log, 0)
        log.write("cycle_end", cycle=1, placed=False, outcomes=[], retries=[], alarm=None, cycle_s=2.0)
        log.write("cycles_end", wall_s=6.0, missed_cycles=0, underruns=0, rss_growth_mb=0.0, stopped="watchdog")
        write_placed_cycle(log, 2)
        log.write("cycles_end", wall_s=4.0, missed_cycles=0, underruns=0, rss_growth_mb=0.0)
    f = cycle_figures(read_log(log_path))
    assert (f["cycles"], f["placed"], f["alarms"], f["cut"]) == (3, 2, 0, 1)
    assert main(["cycles", "report", str(log_path)]) == 0
    assert "| cut | 2 / 3 (1 cut by a stop) | 100.0% |" in capsys.readouterr().out


def test_the_cycles_that_missed_control_cycles_are_counted(tmp_path, capsys):
    with RunLog(tmp_path / "run.jsonl", {"command": "deploy"}) as log:
        # (missed, overruns, steal s, I/O stall s, major faults); a steal of 0.02 s is a tick or two: not counted
        rows = [(0, 0, 0.0, 0.0, 0), (3, 2, 0.2, 0.0, 2), (0, 1, 0.15, 0.3, 1), (1, 0, 0.02, 0.1, 0)]
        for i, (missed, overruns, steal, io, faults) in enumerate(rows):
            write_placed_cycle(
                log,
                i,
                missed_cycles=missed,
                underruns=0,
                work_overruns=overruns,
                steal_s=steal,
                io_stall_s=io,
                major_faults=faults,
            )
        log.write("cycles_end", wall_s=16.0, missed_cycles=4, underruns=0, rss_growth_mb=0.5)
    f = cycle_figures(read_log(tmp_path / "run.jsonl"))
    assert (f["missed_cycles"], f["cycles_with_missed"], f["cycles_with_missed_and_steal_s"]) == (4, 2, 1)
    assert (f["cycles_with_missed_and_io_stall_s"], f["cycles_with_missed_and_major_faults"]) == (1, 1)
    assert (f["cycles_with_steal_s"], f["cycles_with_io_stall_s"]) == (2, 2)  # in all cycles, with a miss or not
    assert main(["cycles", "report", str(tmp_path / "run.jsonl")]) == 0
    out = capsys.readouterr().out
    assert "| 4 (in 2 cycles: 1 with work overruns [2] (3 missed), 1 with host steal >= 0.1 s [2] (3 missed), " in out
    assert "1 with I/O stall >= 10 ms [2] (1 missed), 1 with major page faults [2] (3 missed)) |" in out


def test_where_the_missed_gaps_time_went_is_summed_over_the_cycles(tmp_path, capsys):
    with RunLog(tmp_path / "run.jsonl", {"command": "deploy"}) as log:
        for i, (gaps, wall, cpu, runq, off) in enumerate([(0, 0.0, 0.0, 0.0, 0.0), (2, 0.03, 0.004, 0.02, 0.006)] * 2):
            write_placed_cycle(
                log,
                i,
                miss_gaps=gaps,
                miss_wall_s=wall,
                miss_cpu_s=cpu,
                miss_slept_s=0.0,
                miss_runq_s=runq,
                miss_off_cpu_s=off,
                miss_slices=gaps * 2,
                miss_collections=gaps // 2,
                miss_collecting_s=0.001 * gaps,
            )
        log.write("cycles_end", wall_s=16.0, missed_cycles=4, underruns=0, rss_growth_mb=0.5)
    anatomy = miss_anatomy(read_log(tmp_path / "run.jsonl"))
    assert anatomy == pytest.approx(
        {
            "miss_gaps": 4,
            "miss_wall_s": 0.06,
            "miss_cpu_s": 0.008,
            "miss_runq_s": 0.04,
            "miss_off_cpu_s": 0.012,
            "miss_slept_s": 0.0,
            "miss_slices": 8,
            "miss_collections": 2,
            "miss_collecting_s": 0.004,
        }
    )
    assert main(["cycles", "report", str(tmp_path / "run.jsonl")]) == 0
    assert "| run | 4 | 0.060 s | 0.008 s | 0.040 s | 0.012 s | 0.000 s | 8 | 2 | 0.004 s |" in capsys.readouterr().out


def test_a_log_from_before_the_times_put_on_a_cpu_and_the_collections_has_them_unknown(tmp_path):
    with RunLog(tmp_path / "run.jsonl", {"command": "deploy"}) as log:
        write_placed_cycle(log, 0, **{k: 0.0 for k in MISS_ANATOMY if k not in LATER_ANATOMY})
    anatomy = miss_anatomy(read_log(tmp_path / "run.jsonl"))
    assert anatomy is not None and all(anatomy[k] is None for k in LATER_ANATOMY)
    assert anatomy_table({"old": anatomy}).splitlines()[-1].endswith("| 0.000 s | — | — | — |")


def test_a_log_without_the_gaps_anatomy_has_no_such_row(tmp_path):
    write_run(tmp_path / "run.jsonl")
    assert miss_anatomy(read_log(tmp_path / "run.jsonl")) is None


def test_host_steal_is_read_from_proc_stat(tmp_path):
    stat = tmp_path / "stat"
    stat.write_text("cpu  1806041 3306981 374110 1889507 9876 0 3411 11995 0 0\ncpu0 1 2 3 4 5 6 7 8 0 0\n")
    assert cpu_steal_s(stat) == pytest.approx(11995 / os.sysconf("SC_CLK_TCK"))
    stat.write_text("cpu  1 2 3\n")  # a kernel that does not count steal
    assert cpu_steal_s(stat) is None
    assert cpu_steal_s(tmp_path / "missing") is None


def test_pressure_stalls_are_read_from_proc_pressure(tmp_path):
    (tmp_path / "io").write_text(
        "some avg10=0.04 avg60=0.27 avg300=1.14 total=131027427\nfull avg10=0.00 avg60=0.16 avg300=0.83 total=85494393\n"
    )
    assert pressure_stall_s("io", tmp_path) == pytest.approx(131.027427)
    (tmp_path / "cpu").write_text("full avg10=0.00 total=5\n")  # no "some" line first: not a format we know
    assert pressure_stall_s("cpu", tmp_path) is None
    assert pressure_stall_s("memory", tmp_path) is None  # a kernel without PSI


def test_host_counters_give_a_cycle_what_happened_since_the_last_reading():
    before = HostCounters(steal_s=1.0, cpu_stall_s=None, io_stall_s=2.0, major_faults=3, preemptions=10)
    after = HostCounters(steal_s=1.5, cpu_stall_s=4.0, io_stall_s=2.25, major_faults=5, preemptions=12)
    assert after.since(before) == {
        "steal_s": 0.5,
        "cpu_stall_s": None,  # one reading missing: unknown, not zero
        "io_stall_s": 0.25,
        "major_faults": 2,
        "preemptions": 2,
    }
    now = HostCounters.now()  # this process, read for real
    assert now.major_faults >= 0 and now.preemptions >= 0


def test_a_run_without_its_summary_record_reports_the_driver_counters_as_unknown(tmp_path, capsys):
    write_run(tmp_path / "killed.jsonl", segments=False)
    f = cycle_figures(read_log(tmp_path / "killed.jsonl"))
    assert f["missed_cycles"] is None and f["parts_per_hour"] is None
    assert main(["cycles", "report", str(tmp_path / "killed.jsonl")]) == 0
    assert "| killed | 2 / 3 | 66.7% | 1 | dropped 1, no_grasp 1 | 1 | 6.00 / 7.80 s | — | — | — | — | — |" in (
        capsys.readouterr().out
    )


def test_the_slim_copy_keeps_every_cycle_record_and_the_failed_attempts(tmp_path):
    write_run(tmp_path / "run.jsonl")
    assert main(["cycles", "report", str(tmp_path / "run.jsonl"), "--out", str(tmp_path / "out")]) == 0
    slim = [json.loads(line) for line in gzip.decompress((tmp_path / "out" / "run.jsonl.gz").read_bytes()).splitlines()]
    assert [r["episode"] for r in slim if r["kind"] == "decision"] == [1, 3, 4]
    assert [r["kind"] for r in slim].count("cycle_end") == 3 and slim == slim_records(read_log(tmp_path / "run.jsonl"))
    assert cycle_figures(slim) == cycle_figures(read_log(tmp_path / "run.jsonl"))
    assert (tmp_path / "out" / "cycles.md").read_text().startswith("| run | parts placed |")


def test_a_log_already_in_the_out_folder_is_left_as_it_is(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    write_run(out / "published.jsonl")  # a published log, slimmed by whatever rule held when it was published
    before = (out / "published.jsonl").read_bytes()
    assert main(["cycles", "report", str(out / "published.jsonl"), "--out", str(out)]) == 0
    assert (out / "published.jsonl").read_bytes() == before and not (out / "published.jsonl.gz").exists()
    assert (out / "cycles.md").read_text().count("| published |") == 1


def test_a_log_without_cycles_is_refused_with_its_name(tmp_path, run_cli):
    with RunLog(tmp_path / "episodes.jsonl", {"command": "deploy"}) as log:
        log.write("episode_end", episode=0, outcome="success")
    run_cli(["cycles", "report", str(tmp_path / "episodes.jsonl")]).assert_refused("episodes.jsonl", "no cycle_end")


def _session(log: RunLog, rss: list[float]) -> None:
    for i, mb in enumerate(rss):
        log.write(
            "cycle_end", cycle=i, placed=True, outcomes=["success"], retries=[], alarm=None, cycle_s=4.0, rss_mb=mb
        )


def test_rss_growth_after_warm_up_is_per_session_from_the_warm_up_cycle_on(tmp_path):
    """The resident set a session grows from its cycle WARMUP_CYCLES to its last: the warm-up's growth is not a
    leak, a later one is; each session (a resumed run's `run` record starts one) from its own baseline."""
    warm, later = [50.0 + i for i in range(WARMUP_CYCLES)], [150.0] * 50 + [157.5]
    with RunLog(tmp_path / "run.jsonl", {"command": "deploy"}) as log:
        _session(log, warm + later)
    assert rss_growth_after_warmup(read_log(tmp_path / "run.jsonl")) == pytest.approx(157.5 - warm[-1])
    with RunLog(tmp_path / "run.jsonl", {"command": "deploy"}) as log:  # resumed: a second process, 2 MB more
        _session(log, [300.0] * WARMUP_CYCLES + [302.0])
    assert rss_growth_after_warmup(read_log(tmp_path / "run.jsonl")) == pytest.approx(157.5 - warm[-1])
    with RunLog(tmp_path / "short.jsonl", {"command": "deploy"}) as log:
        _session(log, warm)  # no cycle after the warm-up
    assert rss_growth_after_warmup(read_log(tmp_path / "short.jsonl")) is None


def test_full_collections_are_counted_while_started():
    collections = FullCollections()
    gc.collect()
    assert collections.count == 0  # not started
    collections.start()
    gc.collect(1)  # a young generation: not counted
    gc.collect()
    collections.stop()
    gc.collect()
    assert collections.count == 1 and collections.seconds > 0.0


def test_the_cycles_a_dry_runs_cell_played_behind_the_clock_are_counted(tmp_path, capsys):
    log_path = tmp_path / "behind.jsonl"
    with RunLog(log_path, {"command": "deploy", "cycles": 3}) as log:
        for cycle, backlog in enumerate([0.012, 0.45, 0.02]):
            write_placed_cycle(log, cycle)
            log.write("scored", cycle=cycle, at_goal=True, part=[0.5, 0.1, 0.025], cell_backlog_s=backlog)
    assert cycle_figures(read_log(log_path))["cells_behind"] == 1
    assert main(["cycles", "report", str(log_path)]) == 0
    assert "| 3 / 3 (1 with the simulated cell > 0.1 s behind the clock) |" in capsys.readouterr().out
    write_run(tmp_path / "robot.jsonl")  # no scored records: a robot's log, or a dry run's from before
    assert cycle_figures(read_log(tmp_path / "robot.jsonl"))["cells_behind"] is None
