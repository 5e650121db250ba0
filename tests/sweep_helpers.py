"""Top-level point functions for the executor tests (spawned processes must import them)."""

import os
import time


def square(point, delay_s=0.0):
    start = time.time()
    time.sleep(delay_s)
    return {"value": point.overrides["x"] ** 2, "pid": os.getpid(), "start": start, "end": time.time()}
