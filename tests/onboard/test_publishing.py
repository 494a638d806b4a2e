"""The onboard node's publish scheduling (hd_onboard.publishing), without ROS."""
import math

import numpy as np

from hd_onboard.detectors.levels import ERROR, OK, WARN
from hd_onboard.publishing import InputBook, PublishSchedule, window_table


def test_reports_on_level_change_and_period_of_sample_time():
    s = PublishSchedule(diag_period_s=0.5, residual_rows=100, stale_timeout_s=2.0, t_start=0.0)
    assert s.after_samples(OK, 1_000_000_000, 3) == (True, False)  # first block: a report, rows batched
    assert s.after_samples(OK, 1_400_000_000, 50) == (False, False)  # 0.4 s < period, 50 < 100 rows
    assert s.after_samples(OK, 1_500_000_000, 99) == (True, False)  # period reached
    assert s.last_diag_t == 1.5
    assert s.after_samples(WARN, 1_500_000_001, 1) == (True, True)  # level change: report and rows at once
    assert s.level == WARN
    assert s.after_samples(WARN, 1_600_000_000, 100) == (False, True)  # a full batch of rows
    assert s.after_samples(WARN, 1_700_000_000, 1, force_rows=True) == (False, True)
    assert s.after_samples(ERROR, None, 0) == (True, True) and s.last_diag_t == 0.0  # no sample time yet: t = 0
    s.reset()
    assert (s.level, s.last_diag_t) == (OK, -math.inf)
    assert s.after_samples(OK, 10**9, 0) == (True, False)  # a new core reports at once


def test_no_report_under_unknown_actuator_until_the_stale_timeout():
    s = PublishSchedule(0.5, 100, stale_timeout_s=2.0, t_start=100.0)
    assert not s.may_report("", 101.9)
    assert s.may_report("", 102.0) and s.may_report("EMA-1", 100.0)


def test_stale_watchdog_closes_windows_once_and_reports_every_tick():
    s = PublishSchedule(0.5, 100, stale_timeout_s=2.0, t_start=0.0)
    assert s.watchdog(None, 50.0) == (False, False)  # never had joint states: not STALE (inputs say missing)
    assert s.watchdog(10.0, 12.0) == (False, False)  # exactly the timeout: not yet
    assert s.watchdog(10.0, 12.1) == (True, True) and s.stale
    assert s.watchdog(10.0, 13.0) == (False, True)  # still STALE: report again, windows already closed
    assert s.watchdog(13.0, 13.1) == (False, False) and not s.stale  # joint states back
    assert s.watchdog(13.0, 15.5) == (True, True)  # a new silence closes again


def test_input_book_reports_the_first_undecodable_only():
    b = InputBook(("/a", "/b"))
    assert b.n_msgs == {"/a": 0, "/b": 0} and b.last_wall == {"/a": None, "/b": None}
    assert [b.bad() for _ in range(5)] == [True, True, True, False, False] and b.n_bad == 5


def test_window_table_unions_keys_in_sorted_order():
    keys, tab = window_table([{"b": 1.0, "a": 2}, {"c": 3.0, "a": 4.0}])
    assert keys == ["a", "b", "c"]
    np.testing.assert_array_equal(tab, [[2.0, 1.0, np.nan], [4.0, np.nan, 3.0]])
