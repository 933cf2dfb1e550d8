"""The kernel cache's entries: read back bit for bit with their large arrays memory-mapped (psf.kernel_io), and
derived entries (psf.cache.cached_arrays) made once, then loaded."""
import numpy as np
import pytest

from psf.cache import cached_arrays, derived_key, load, store
from psf.engine import KernelSet
from psf.kernel_io import MAP_BYTES, load_kernels, read_members, save_kernels


def _kernel_set() -> KernelSet:
    rng = np.random.default_rng(3)
    field = rng.random((2, 2, 2, 257, 257), dtype=np.float32)  # 2.1 MB: mapped
    return KernelSet(rng.random((2, 129, 129), dtype=np.float32), np.array([450.0, 550.0]), 1.55,
                     np.array([0.01, 0.02]), np.array([0.3, 0.4]), np.array([1.0, 1.1]), {"method": "test"},
                     field_kernels=field, field_power=rng.random((2, 2, 2)), period_um=(60.0, 120.0),
                     distance_mm=2.0, image_distance_um=6000.0)


def test_a_kernel_file_reads_back_bit_for_bit_with_its_large_arrays_mapped(tmp_path):
    ks = _kernel_set()
    path = save_kernels(tmp_path / "k.npz", ks)
    back = load_kernels(path)
    for name in ("kernels", "field_kernels", "field_power", "wavelengths_nm", "energy_outside"):
        assert getattr(back, name).tobytes() == getattr(ks, name).tobytes() and getattr(back, name).dtype == getattr(
            ks, name).dtype
    assert (back.params, back.period_um, back.distance_mm, back.pixel_um) == (ks.params, ks.period_um, 2.0, 1.55)
    assert ks.field_kernels.nbytes >= MAP_BYTES > ks.kernels.nbytes
    assert isinstance(back.field_kernels.base, np.memmap) and not back.field_kernels.flags.writeable
    assert not isinstance(back.kernels.base, np.memmap) and back.kernels.flags.writeable  # small: read
    with np.load(path) as z:  # still an ordinary .npz
        assert z["field_kernels"].tobytes() == ks.field_kernels.tobytes()


def test_a_truncated_entry_is_a_miss_not_an_error(tmp_path):
    store("k", _kernel_set(), tmp_path)
    path = tmp_path / "k.npz"
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])
    assert load("k", tmp_path) is None
    with pytest.raises((OSError, ValueError)):
        read_members(path)


def test_a_derived_entry_is_made_once_then_loaded(tmp_path):
    made = []

    def make():
        made.append(1)
        return {"maps": np.arange(3 * 300 * 300, dtype=np.float32).reshape(3, 300, 300), "rank": np.asarray(4)}
    first = cached_arrays("test-1", ("a", "b"), make, tmp_path, shape=[300, 300])
    again = cached_arrays("test-1", ("a", "b"), make, tmp_path, shape=[300, 300])
    assert made == [1] and again["maps"].tobytes() == first["maps"].tobytes() and int(again["rank"]) == 4
    assert isinstance(again["maps"].base, np.memmap)
    assert (tmp_path / f"{derived_key('test-1', ('a', 'b'), shape=[300, 300])}.npz").is_file()
    cached_arrays("test-1", ("a", "b"), make, tmp_path, shape=[300, 301])  # another parameter: another entry
    cached_arrays("test-1", ("a", "c"), make, tmp_path, shape=[300, 300])  # another source: another entry
    cached_arrays("test-1", ("a", None), make, tmp_path, shape=[300, 300])  # a source not cached: made, not kept
    cached_arrays("test-1", ("a", None), make, tmp_path, shape=[300, 300])
    assert len(made) == 5 and len(list(tmp_path.glob("*.npz"))) == 3
