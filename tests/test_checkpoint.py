import numpy as np
import pytest
from kinswarm.actors.files.checkpoint import CheckpointError, load_checkpoint, save_checkpoint


def arrays():
    return {"keys": np.arange(5, dtype=np.int64), "phi": np.linspace(0, 1, 15).reshape(5, 3)}


def test_round_trip(tmp_path):
    p = tmp_path / "a1.npz"
    save_checkpoint(p, arrays(), {"agent": "a1", "epochs_trained": 3})
    got, meta = load_checkpoint(p, agent="a1")
    for k, v in arrays().items():
        np.testing.assert_array_equal(got[k], v)
    assert meta["epochs_trained"] == 3
    assert not [f for f in tmp_path.iterdir() if f.name != "a1.npz"]  # no temp file left


def test_torn_file_is_refused(tmp_path):
    p = tmp_path / "a1.npz"
    save_checkpoint(p, arrays(), {"agent": "a1"})
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    with pytest.raises(CheckpointError, match="a1.npz"):
        load_checkpoint(p)


def test_flipped_byte_is_refused(tmp_path):
    p = tmp_path / "a1.npz"
    big = {"phi": np.zeros((200, 9))}
    save_checkpoint(p, big, {"agent": "a1"})
    raw = bytearray(p.read_bytes())
    # np.savez stores arrays uncompressed: flip a byte inside the phi payload
    i = raw.find(np.zeros(8).tobytes() * 4) + 5
    raw[i] ^= 0xFF
    p.write_bytes(bytes(raw))
    with pytest.raises(CheckpointError, match="checksum|readable"):
        load_checkpoint(p)


def test_foreign_npz_and_wrong_agent(tmp_path):
    p = tmp_path / "x.npz"
    np.savez(p, a=np.zeros(3))
    with pytest.raises(CheckpointError, match="no kinswarm header"):
        load_checkpoint(p)
    q = tmp_path / "a2.npz"
    save_checkpoint(q, arrays(), {"agent": "a2"})
    with pytest.raises(CheckpointError, match="belongs to agent 'a2'"):
        load_checkpoint(q, agent="a1")
    with pytest.raises(CheckpointError, match="no such checkpoint"):
        load_checkpoint(tmp_path / "none.npz")


def test_a_torn_newest_checkpoint_falls_back_to_the_previous_one(tmp_path):
    from kinswarm.actors.files.checkpoint import load_latest, previous

    p = tmp_path / "a1.npz"
    save_checkpoint(p, arrays(), {"agent": "a1", "run_epoch": 4})
    newer = {k: v + 1 for k, v in arrays().items()}
    save_checkpoint(p, newer, {"agent": "a1", "run_epoch": 5})
    assert previous(p).is_file()
    got, meta, used, refused = load_latest(p, agent="a1")
    assert used == p and meta["run_epoch"] == 5 and not refused
    p.write_bytes(p.read_bytes()[:100])  # torn
    got, meta, used, refused = load_latest(p, agent="a1")
    assert used == previous(p) and meta["run_epoch"] == 4 and "a1.npz" in refused[0]
    np.testing.assert_array_equal(got["phi"], arrays()["phi"])
    previous(p).write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="a1.prev.npz"):
        load_latest(p, agent="a1")
