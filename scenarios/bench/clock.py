"""The closed loop's clock: which tasks are due at each physics step.

Physics steps at ``rates.physics_hz``; control, localization and the safety laser run at
their own rates on that clock (:class:`Schedule`), and :class:`SensorClock` tells the
bench at each step which of the three are due.

Examples
--------
>>> [n for n in range(1, 13) if Schedule(50.0, 240.0).due(n)]   # every 4 or 5 steps
[5, 10]
"""

from __future__ import annotations

import math

from scenarios.spec.scenario import Rates

__all__ = ["Schedule", "SensorClock"]


class Schedule:
    """Fire at ``rate_hz`` on a physics clock of ``physics_hz``, with no drift.

    Step ``n`` is due when ``floor(n * rate / physics)`` increases, so a 50 Hz task on a
    240 Hz clock fires 50 times per simulated second, every 4 or 5 steps.

    Examples
    --------
    >>> schedule = Schedule(50.0, 240.0)
    >>> sum(schedule.due(n) for n in range(1, 241))
    50
    """

    def __init__(self, rate_hz: float, physics_hz: float) -> None:
        self.ratio = rate_hz / physics_hz

    def _count(self, step: int) -> int:
        """Return how many times the task ran up to physics step ``step``."""
        return math.floor(step * self.ratio + 1e-9)

    def due(self, step: int) -> bool:
        """Return whether the task runs at physics step ``step`` (counted from 1)."""
        return self._count(step) > self._count(step - 1)

    def next_due(self, step: int) -> int:
        """Return the first step after ``step`` at which the task runs.

        The same decisions as :meth:`due` (the count is monotone in the step), found
        from the rate in a few evaluations instead of one per physics step: the closed
        loop asks once per firing, not three times per tick.

        Examples
        --------
        >>> schedule = Schedule(50.0, 240.0)
        >>> schedule.next_due(0), schedule.next_due(5), schedule.next_due(10)
        (5, 10, 15)
        >>> [n for n in range(1, 30) if schedule.due(n)]
        [5, 10, 15, 20, 24, 29]
        """
        target = self._count(step) + 1
        # The real-valued solution of count(m) = target, then exact steps to the first m.
        candidate = max(step + 1, math.ceil((target - 1e-9) / self.ratio))
        while candidate > step + 1 and self._count(candidate - 1) >= target:
            candidate -= 1
        while self._count(candidate) < target:
            candidate += 1
        return candidate


class SensorClock:
    """Which of control, localization and safety are due at each physics step.

    Each schedule's next step is looked up once per firing; a step before the earliest of
    them is answered with ``None`` at the cost of one comparison (most steps: nothing is
    due), the others with the three flags in that order.

    Examples
    --------
    >>> from scenarios.spec.scenario import Rates
    >>> clock = SensorClock(Rates(physics_hz=240.0, control_hz=50.0, localization_hz=25.0,
    ...                           safety_hz=12.5))
    >>> ticks = [clock.tick() for _ in range(20)]
    >>> [step for step, due in enumerate(ticks, start=1) if due is not None]
    [5, 10, 15, 20]
    >>> ticks[9], ticks[19]
    ((True, True, False), (True, True, True))
    """

    def __init__(self, rates: Rates) -> None:
        self._schedules = (Schedule(rates.control_hz, rates.physics_hz),
                           Schedule(rates.localization_hz, rates.physics_hz),
                           Schedule(rates.safety_hz, rates.physics_hz))
        self._due_steps = [schedule.next_due(0) for schedule in self._schedules]
        self._next_due = min(self._due_steps)
        self._step = 0

    def tick(self) -> tuple[bool, bool, bool] | None:
        """Advance one physics step; return ``(control, localization, safety)`` due, or None."""
        self._step += 1
        n = self._step
        if n < self._next_due:
            return None
        steps = self._due_steps
        due = (steps[0] == n, steps[1] == n, steps[2] == n)
        for index, schedule in enumerate(self._schedules):
            if due[index]:
                steps[index] = schedule.next_due(n)
        self._next_due = min(steps)
        return due
