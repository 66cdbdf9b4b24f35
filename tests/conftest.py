import os

import jax
import numpy as np
from hypothesis import HealthCheck, settings

jax.config.update("jax_enable_x64", True)

# CI runs on 2 cores: keep property-based tests small but meaningful.
settings.register_profile(
    "ci",
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
    derandomize=True,
)
settings.register_profile("dev", max_examples=100, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

EPS = np.finfo(np.float64).eps
