"""The training monitor's TensorBoard writer: what it writes, TensorBoard reads back exactly; it starts
no thread, so closing it cannot wait on one (a stop signal during training once left the worker joining
tensorboard's writer thread until its grace ran out)."""

from __future__ import annotations

import threading

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from motorlab.rl.monitor import ScalarWriter

pytestmark = pytest.mark.fast

TAGS = st.sampled_from(["train/episode_return", "eval/return_mean", "eval/solved", "model/one_step_mse"])
SCALARS = st.lists(st.tuples(TAGS, st.floats(-1e6, 1e6, width=32), st.integers(0, 10**9)), max_size=40)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(scalars=SCALARS)
def test_tensorboard_reads_back_every_scalar_written(tmp_path_factory, scalars):
    folder = tmp_path_factory.mktemp("tb")
    writer = ScalarWriter(folder)
    for tag, value, step in scalars:
        writer.add_scalar(tag, value, step)
    writer.close()
    events = EventAccumulator(str(folder), size_guidance={"scalars": 0})
    events.Reload()
    for tag in {t for t, _, _ in scalars}:
        assert [(e.step, e.value) for e in events.Scalars(tag)] == [(s, v) for t, v, s in scalars if t == tag]
    assert set(events.Tags()["scalars"]) == {t for t, _, _ in scalars}


def test_the_writer_starts_no_thread_and_two_in_one_second_write_two_files(tmp_path):
    before = threading.active_count()
    a, b = ScalarWriter(tmp_path), ScalarWriter(tmp_path)
    assert threading.active_count() == before
    a.add_scalar("x", 1.0, 1)
    a.flush()
    assert len(list(tmp_path.glob("events.out.tfevents.*"))) == 2
    a.close()
    b.close()
