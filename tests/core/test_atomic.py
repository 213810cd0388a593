import os

import pytest

from grip.core.atomic import atomic_write, atomic_write_text


def test_atomic_write_gives_plain_open_permissions_and_keeps_old_file_on_error(tmp_path) -> None:
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    out = tmp_path / "out.txt"
    atomic_write_text(out, "hello")
    assert out.read_text() == "hello"
    assert os.stat(out).st_mode & 0o777 == os.stat(plain).st_mode & 0o777

    def boom(f) -> None:
        f.write(b"partial")
        raise RuntimeError("disk on fire")

    with pytest.raises(RuntimeError):
        atomic_write(out, boom)
    assert out.read_text() == "hello"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt", "plain.txt"]
