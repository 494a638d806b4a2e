import itertools
import os

import pytest

_counter = itertools.count()


@pytest.fixture
def domain_id():
    """A ROS domain id unique to this test (pytest-xdist worker x counter), so tests never cross-talk."""
    w = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    wi = int(w[2:]) if w[2:].isdigit() else 0
    return 100 + (wi * 16 + next(_counter)) % 120
