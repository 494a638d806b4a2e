import itertools
import os

import pytest

_counter = itertools.count()


@pytest.fixture
def domain_id():
    """A ROS domain id unique to this test (pytest-xdist worker x counter), so tests never cross-talk."""
    w = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    wi = int(w[2:]) if w[2:].isdigit() else 0
    # HDPHM_TEST_DOMAIN_BASE lets several checkouts run ROS tests on one machine at once without cross-talk
    base = int(os.environ.get("HDPHM_TEST_DOMAIN_BASE", "100"))
    span = int(os.environ.get("HDPHM_TEST_DOMAIN_SPAN", "120"))
    return base + (wi * 16 + next(_counter)) % span
