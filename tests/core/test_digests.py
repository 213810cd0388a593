"""Records of what a file held (:mod:`grip.core.digests`): the resume checks' ground."""

from __future__ import annotations

import hashlib
import os

from grip.core.digests import FileDigests, change_text, file_sha256, same_contents


def test_record_holds_the_sha256_and_the_stat(tmp_path) -> None:
    f = tmp_path / "model.pt"
    f.write_bytes(b"weights v1")
    rec = FileDigests().record(f)
    assert rec["sha256"] == hashlib.sha256(b"weights v1").hexdigest() == file_sha256(f)
    st = os.stat(f)
    assert (rec["size"], rec["mtime_ns"], rec["ctime_ns"]) == (10, st.st_mtime_ns, st.st_ctime_ns)
    assert FileDigests().record(tmp_path / "missing") is None
    assert FileDigests().record(tmp_path) is None  # a folder is not a readable file


def test_an_unchanged_file_is_not_read_again(tmp_path) -> None:
    files = [tmp_path / f"r{i}.npz" for i in range(3)]
    for i, f in enumerate(files):
        f.write_bytes(bytes([i]) * 100)
    first = FileDigests()
    known = {str(f.resolve()): first.record(f) for f in files}
    assert first.hashed == 3
    assert [first.record(f) for f in files] == list(known.values())
    assert first.hashed == 3  # hashed once per object
    resumed = FileDigests(known)  # a later run with the records of the earlier one
    assert [resumed.record(f) for f in files] == list(known.values())
    assert resumed.hashed == 0


def test_a_file_replaced_in_place_is_seen_even_with_its_old_size_and_mtime(tmp_path) -> None:
    f = tmp_path / "policy.pt"
    f.write_bytes(b"policy A")
    old = FileDigests().record(f)
    f.write_bytes(b"policy B")  # same size
    os.utime(f, ns=(old["mtime_ns"], old["mtime_ns"]))  # and the old mtime (cp -p, rsync -t)
    new = FileDigests({str(f.resolve()): old}).record(f)
    assert new["sha256"] != old["sha256"] and not same_contents(old, new)
    text = change_text(f, old, new)
    assert str(f) in text and old["sha256"][:12] in text and new["sha256"][:12] in text


def test_rewritten_with_the_same_bytes_is_the_same_contents(tmp_path) -> None:
    f = tmp_path / "take.npz"
    f.write_bytes(b"same")
    old = FileDigests().record(f)
    f.unlink()
    f.write_bytes(b"same")
    new = FileDigests({str(f.resolve()): old}).record(f)
    assert same_contents(old, new)
    assert same_contents(None, None) and not same_contents(old, None)
    assert not same_contents({"sha256": 1}, new)  # a damaged record is never "the same"
    assert "gone" in change_text(f, old, None)
