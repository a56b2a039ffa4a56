"""Guardians that misbehave, for the benchmark's error paths."""

import time

from guardians.base import Guardian, inactive_action


class Boom(Guardian):
    name = "boom"

    def reset(self, **kw):
        super().reset(**kw)
        self.n = 0

    def act(self, obs, info):
        self.n += 1
        if self.n == 3:
            raise RuntimeError("guardian exploded")
        return inactive_action()


class Sleepy(Guardian):
    name = "sleepy"

    def act(self, obs, info):
        time.sleep(0.05)
        return inactive_action()
