"""A cache entry comes back exactly as written, or not at all: every header field and every byte of
content is checked before a cache uses it (`orthosim.storage.cacheentry`)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from orthosim.errors import DamagedFileError
from orthosim.storage import cacheentry as E


def _arrays():
    return {"vertices": np.arange(12, dtype=np.float64).reshape(4, 3), "faces": np.array([[0, 1, 2]], np.int64),
            "header": np.array('{"teeth": [11]}')}


def test_arrays_come_back_bit_identical(tmp_path):
    path = tmp_path / "k1.npz"
    E.write_arrays(path, "dentition", "k1", _arrays())
    back = E.read_arrays(path, "dentition", "k1")
    assert back.keys() == _arrays().keys()
    for name, a in _arrays().items():
        assert back[name].dtype == a.dtype and np.array_equal(back[name], a)


@pytest.mark.parametrize("kind, key, problem", [
    ("spheretree", "k1", "'dentition' entry where a 'spheretree' one"),
    ("dentition", "k2", "another entry's content"),
])
def test_an_entry_of_another_kind_or_key_is_damaged(tmp_path, kind, key, problem):
    path = tmp_path / "k1.npz"
    E.write_arrays(path, "dentition", "k1", _arrays())
    with pytest.raises(DamagedFileError, match=problem):
        E.read_arrays(path, kind, key)


def test_an_entry_of_another_format_or_without_header_is_damaged(tmp_path, monkeypatch):
    path = tmp_path / "k1.npz"
    monkeypatch.setattr(E, "ENTRY_FORMAT", 0)
    E.write_arrays(path, "dentition", "k1", _arrays())
    monkeypatch.undo()
    with pytest.raises(DamagedFileError, match="entry format 0, this orthosim reads 1"):
        E.read_arrays(path, "dentition", "k1")
    with open(path, "wb") as fh:
        np.savez(fh, **_arrays())  # a plain .npz, as written before entries had headers
    with pytest.raises(DamagedFileError, match="no entry header"):
        E.read_arrays(path, "dentition", "k1")


def test_a_changed_shape_with_the_same_bytes_fails_the_checksum(tmp_path):
    path = tmp_path / "k1.npz"
    E.write_arrays(path, "dentition", "k1", _arrays())
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["vertices"] = arrays["vertices"].reshape(3, 4)  # same 96 bytes, another array
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    with pytest.raises(DamagedFileError, match="checksum mismatch") as err:
        E.read_arrays(path, "dentition", "k1")
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_a_json_entry_with_one_figure_changed_is_damaged_and_a_missing_one_is_absent(tmp_path):
    path = tmp_path / "fit.json"
    E.write_json(path, "treefit", "fit", {"sov_sum": 0.25, "leaves": 4096})
    assert E.read_json(path, "treefit", "fit") == {"sov_sum": 0.25, "leaves": 4096}
    document = json.loads(path.read_text())
    document["payload"]["sov_sum"] = 0.24
    path.write_text(json.dumps(document))
    with pytest.raises(DamagedFileError, match="checksum mismatch"):
        E.read_json(path, "treefit", "fit")
    with pytest.raises(FileNotFoundError):
        E.read_json(tmp_path / "absent.json", "treefit", "absent")


def _every_kind_of_member():
    rng = np.random.default_rng(5)
    return {"f8": rng.normal(size=(7, 3)), "f4": rng.normal(size=5).astype(np.float32), "i8": np.arange(6, dtype=np.int64),
            "u1": np.arange(4, dtype=np.uint8), "b1": np.array([True, False, True]), "big": np.arange(3, dtype=">i4"),
            "scalar": np.array(2.5), "empty": np.zeros((0, 3)), "text": np.array("é, and a long text " * 20),
            "fortran": np.asfortranarray(rng.normal(size=(3, 4))), "wide": np.zeros((2, 3, 4, 5), np.int16)}


def test_members_read_as_numpy_reads_them(tmp_path):
    """The entry reader parses the members `np.save` writes itself (numpy's header parsing was most
    of a warm start's cache reads); every member comes back as `np.load` gives it: dtype, shape,
    bytes, writable. A Fortran-ordered member takes numpy's own reader."""
    path = tmp_path / "k1.npz"
    E.write_arrays(path, "dentition", "k1", _every_kind_of_member())
    back = E.read_arrays(path, "dentition", "k1")
    with np.load(path, allow_pickle=False) as z:
        for name in _every_kind_of_member():
            want = z[name]
            assert back[name].dtype == want.dtype and back[name].shape == want.shape, name
            assert back[name].tobytes(order="A") == want.tobytes(order="A") and np.array_equal(back[name], want), name
            assert back[name].flags.writeable, name
    assert back["fortran"].flags.f_contiguous


def test_a_member_whose_bytes_changed_fails_the_zips_crc(tmp_path):
    path = tmp_path / "k1.npz"
    E.write_arrays(path, "dentition", "k1", _arrays())
    data = bytearray(path.read_bytes())
    at = data.find(np.arange(12, dtype=np.float64).tobytes())
    data[at + 3] ^= 0x10  # a flipped bit in the vertices: zip's CRC-32 fails before the entry's checksum
    path.write_bytes(bytes(data))
    with pytest.raises(DamagedFileError, match="unreadable"):
        E.read_arrays(path, "dentition", "k1")
