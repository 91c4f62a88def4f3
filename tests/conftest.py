"""Shared fixtures: arms are loaded once per session (URDF parsing is the slow part)."""

import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.model.arm import Arm


@pytest.fixture(scope="session")
def ur5() -> Arm:
    base = pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.2, 0.7), np.array([0.3, -0.4, 0.2]))
    return Arm.from_robot_name("ur5", name="ur5", base_placement=base)


@pytest.fixture(scope="session")
def panda() -> Arm:
    return Arm.from_robot_name("panda", name="panda")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)



@pytest.fixture(autouse=True)
def _sigint_left_as_found(request):
    """Every test starts with the SIGINT handler and signal mask the session started with.

    A process whose SIGINT is ignored or blocked ignores Ctrl-C and passes that on to every
    process it starts. A test after which they differ is named in a warning, and they are put
    back, so that the tests of Ctrl-C do not depend on the order the suite runs in.
    """
    import signal
    import warnings

    before = signal.getsignal(signal.SIGINT)
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    yield
    after = signal.getsignal(signal.SIGINT)
    mask_after = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    if after is not before or mask_after != mask:
        signal.signal(signal.SIGINT, before)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        warnings.warn(f"{request.node.nodeid} left SIGINT changed: handler {before!r} -> "
                      f"{after!r}, blocked signals {sorted(mask)} -> {sorted(mask_after)} "
                      "(put back)", stacklevel=1)
