import pytest


def _cuda_available() -> bool:
    try:
        from rodwarp import _warp

        _warp.init()
        import warp as wp

        return wp.is_cuda_available()
    except Exception:
        return False


def pytest_collection_modifyitems(config, items):
    if _cuda_available():
        return
    skip = pytest.mark.skip(reason="no CUDA device: GPU tests skipped")
    for item in items:
        if "cuda" in item.keywords:
            item.add_marker(skip)
