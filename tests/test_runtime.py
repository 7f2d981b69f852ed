"""What a run may take from the machine: threads and workers capped by the CPUs, and one run
at a time per output folder (a lock the operating system releases however the run ends)."""

import os
import signal
import subprocess
import sys
import time

import pytest

from iout_mj.errors import IoutError
from iout_mj.runtime import OutputBusyError, cpu_bounded, output_lock, usable_cpus

HOLD = """
import sys, time
from pathlib import Path
from iout_mj.runtime import output_lock
with output_lock(Path(sys.argv[1]), "holder"):
    print("held", flush=True)
    time.sleep(60)
"""


def test_usable_cpus_is_the_affinity_of_this_process():
    assert usable_cpus() == len(os.sched_getaffinity(0)) >= 1


@pytest.mark.parametrize("bad", [-1, usable_cpus() + 1, 1000, 1.5, "2", True, None])
def test_counts_beyond_the_cpus_say_what_is_accepted(bad):
    with pytest.raises(IoutError, match=rf"accepted an integer from 0 to {usable_cpus()}"):
        cpu_bounded(bad, "nthread", 0)


def test_counts_within_the_cpus_are_returned():
    assert [cpu_bounded(n, "workers", 1) for n in range(1, usable_cpus() + 1)] == list(
        range(1, usable_cpus() + 1)
    )


def test_a_second_holder_is_refused_until_the_first_is_done(tmp_path):
    with output_lock(tmp_path, "evaluate"):
        busy = rf"{tmp_path} is in use by iout-mj evaluate"
        with pytest.raises(OutputBusyError, match=busy), output_lock(tmp_path, "figures"):
            pass
        assert f"pid {os.getpid()}" in (tmp_path / ".lock").read_text()
    with output_lock(tmp_path, "figures"):  # released on leaving the block
        pass


def test_a_killed_holder_releases_the_folder(tmp_path):
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(tmp_path)], stdout=subprocess.PIPE, text=True
    )
    assert holder.stdout.readline().strip() == "held"
    with pytest.raises(OutputBusyError, match=f"pid {holder.pid}"), output_lock(tmp_path, "x"):
        pass
    holder.send_signal(signal.SIGKILL)  # no cleanup runs in the holder
    holder.wait()
    start = time.perf_counter()
    with output_lock(tmp_path, "evaluate"):
        assert time.perf_counter() - start < 1


def test_a_lock_that_cannot_be_made_says_so(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(IoutError, match="cannot write to"), output_lock(blocker, "evaluate"):
        pass
