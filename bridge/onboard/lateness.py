"""How far a control loop falls behind its clock: steps that come late and gaps, counted,
the worst kept, and a warning when it matters.

A step is late when it starts more than `LATE_FACTOR` periods after the last; a few are
normal on a busy computer, so the warning waits for `WARN_AFTER` of them. A gap (at least
`GAP_S` without a step: the process stalled, the clock jumped) is said every time: the
state the controller then works from is old, and the commands it holds went unrevised.
"""

from __future__ import annotations

from dataclasses import dataclass

LATE_FACTOR = 1.5  # a control step this many periods after the last is late
WARN_AFTER = 10  # late steps before the warning
GAP_S = 1.0  # this long without a step is a gap


@dataclass
class Lateness:
    """The lateness of one loop with period `period_s` (call `tick` at each step's start)."""

    period_s: float
    steps: int = 0
    late_steps: int = 0
    gaps: int = 0
    worst_late_s: float = 0.0  # the most a step came after its period
    _last: float | None = None

    def tick(self, now_s: float) -> tuple[float, str | None]:
        """A step starts at `now_s`: the time since the last step's start (one period for
        the first) and a warning to say, if this step calls for one."""
        elapsed = self.period_s if self._last is None else now_s - self._last
        self._last = now_s
        self.steps += 1
        if elapsed <= LATE_FACTOR * self.period_s:
            return elapsed, None
        self.late_steps += 1
        self.worst_late_s = max(self.worst_late_s, elapsed - self.period_s)
        if elapsed >= GAP_S:
            self.gaps += 1
            return elapsed, (f"control loop: a gap of {elapsed:.2f} s before step {self.steps} "
                             f"(period {self.period_s:g} s)")
        if self.late_steps == WARN_AFTER:
            return elapsed, (f"control loop falls behind the clock: {self.late_steps} of "
                             f"{self.steps} steps late, this one {elapsed:.2f} s after the last "
                             f"(period {self.period_s:g} s)")
        return elapsed, None

    def pause(self) -> None:
        """The loop stops stepping on purpose (waiting between runs, to resume): the next
        step is not late."""
        self._last = None

    def summary(self) -> str | None:
        """One line for the end of a run, or None if no step was late."""
        if not self.late_steps:
            return None
        gaps = f", {self.gaps} gaps of {GAP_S:g} s or more" if self.gaps else ""
        return (f"control loop: {self.late_steps} of {self.steps} steps late (> {LATE_FACTOR:g} "
                f"periods after the last){gaps}, the worst by {self.worst_late_s:.2f} s")
