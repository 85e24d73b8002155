"""dynamics fit's default passes: 50 on plenty of data, more on little, so every fit takes at least
MIN_GRADIENT_STEPS gradient steps (capped, so a tiny dataset is not scored thousands of times)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from motorlab.dynamics.train import DEFAULT_EPOCHS, MAX_AUTO_EPOCHS, MIN_GRADIENT_STEPS, auto_epochs
from motorlab.kinds.dynamics import DYNAMICS_FIT

pytestmark = pytest.mark.fast


@given(rows=st.integers(1, 5_000_000), batch=st.integers(1, 10_000))
def test_auto_epochs_give_enough_gradient_steps_within_their_bounds(rows, batch):
    epochs = auto_epochs(rows, batch)
    per_epoch = -(-rows // batch)
    assert DEFAULT_EPOCHS <= epochs <= MAX_AUTO_EPOCHS
    assert epochs * per_epoch >= MIN_GRADIENT_STEPS or epochs == MAX_AUTO_EPOCHS
    assert epochs == DEFAULT_EPOCHS or (epochs - 1) * per_epoch < MIN_GRADIENT_STEPS  # no more passes than needed


def test_plenty_of_data_keeps_fifty_and_a_small_arm_dataset_gets_more():
    assert auto_epochs(900_000, 2000) == 50  # Reacher's 20,000 episodes: 450 steps a pass
    assert auto_epochs(36_000, 2000) == 223  # 400 episodes of 100 steps, 10% held out: 18 steps a pass
    assert DYNAMICS_FIT.make(transitions="x").epochs is None and DYNAMICS_FIT.make(transitions="x", epochs=7).epochs == 7
