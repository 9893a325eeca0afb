"""The PyBullet client wrapper: life cycle, fixed stepping, engine-time accounting."""

import pybullet
import pytest

from sim.client import DEFAULT_TIME_STEP, GRAVITY, SimClient


def _drop_a_ball(sim: SimClient) -> int:
    bullet = sim.bullet
    shape = bullet.createCollisionShape(bullet.GEOM_SPHERE, radius=0.1)
    return bullet.createMultiBody(
        baseMass=1.0, baseCollisionShapeIndex=shape, basePosition=[0, 0, 5]
    )


def test_defaults_are_direct_fixed_step_with_gravity():
    with SimClient() as sim:
        assert not sim.gui
        assert sim.time_step == DEFAULT_TIME_STEP
        assert sim.bullet.getConnectionInfo()["connectionMethod"] == pybullet.DIRECT
        params = sim.bullet.getPhysicsEngineParameters()
        assert params["fixedTimeStep"] == pytest.approx(DEFAULT_TIME_STEP)
        assert params["numSubSteps"] == 0
        assert params["gravityAccelerationZ"] == pytest.approx(-GRAVITY)


def test_step_advances_simulated_time_and_physics():
    with SimClient(time_step=0.01) as sim:
        ball = _drop_a_ball(sim)
        sim.step(50)
        assert sim.steps == 50
        assert sim.sim_time == pytest.approx(0.5)
        z = sim.bullet.getBasePositionAndOrientation(ball)[0][2]
        # Free fall for 0.5 s (semi-implicit Euler lands within a step's worth of it).
        assert z == pytest.approx(5.0 - 0.5 * GRAVITY * 0.5**2, abs=0.05)


def test_engine_time_counts_stepping_and_timed_blocks():
    with SimClient() as sim:
        assert sim.engine_time_s == 0.0
        sim.step(10)
        after_steps = sim.engine_time_s
        assert after_steps > 0.0
        with sim.engine_timer():
            sim.bullet.rayTestBatch([[0, 0, 1]] * 100, [[0, 0, -1]] * 100)
        assert sim.engine_time_s > after_steps
        before = sim.engine_time_s
        _ = sum(range(1000))  # our own Python outside the timer is not engine time
        assert sim.engine_time_s == before


def test_engine_timer_counts_even_when_the_block_raises():
    with SimClient() as sim:
        with pytest.raises(RuntimeError), sim.engine_timer():
            raise RuntimeError("boom")
        assert sim.engine_time_s > 0.0


def test_clients_are_independent():
    with SimClient() as first, SimClient() as second:
        assert first.client_id != second.client_id
        ball = _drop_a_ball(first)
        assert first.bullet.getNumBodies() == 1
        assert second.bullet.getNumBodies() == 0
        second.step(100)
        assert first.bullet.getBasePositionAndOrientation(ball)[0][2] == 5.0
        assert first.steps == 0


def test_close_is_idempotent_and_final():
    sim = SimClient()
    sim.close()
    sim.close()
    assert sim.closed
    with pytest.raises(RuntimeError, match="closed"):
        sim.step()


def test_context_manager_closes_on_error():
    with pytest.raises(ValueError, match="inside"), SimClient() as sim:
        raise ValueError("inside")
    assert sim.closed


@pytest.mark.parametrize("time_step", [0.0, -0.01, 0.5, float("nan")])
def test_rejects_bad_time_steps(time_step):
    with pytest.raises(ValueError, match="time_step must be in"):
        SimClient(time_step=time_step)


def test_rejects_negative_gravity_and_steps():
    with pytest.raises(ValueError, match="gravity"):
        SimClient(gravity=-9.81)
    with SimClient() as sim, pytest.raises(ValueError, match="n must be >= 0"):
        sim.step(-1)


def test_repr_names_mode_and_time():
    with SimClient() as sim:
        assert "DIRECT" in repr(sim)
    assert "closed" in repr(sim)
