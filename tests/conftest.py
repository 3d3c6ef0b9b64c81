"""Shared test fixtures."""

from __future__ import annotations

import pytest

pytest_plugins = ["pytester"]


@pytest.fixture
def torch_one_thread():
    """Run a test with one torch thread (bit-reproducible CPU results), then restore."""
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)
