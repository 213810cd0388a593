import pytest

from grip.kinematics.sweep import find_runs, parse_counts, sensor_sets, sweep_table


def test_sensor_sets_follow_grip_order() -> None:
    sets = sensor_sets((2, 3, 6))
    assert [s.name for s in sets] == ["imu2_nopress", "imu3_nopress", "imu6_nopress",
                                      "imu2_press", "imu3_press", "imu6_press"]  # fmt: skip
    assert sets[1].sites == ("L_Foot", "R_Foot", "L_Wrist")
    assert sets[2].sites[-2:] == ("Pelvis", "Head")


@pytest.mark.parametrize("text", ["", "2,x", "0", "7"])
def test_parse_counts_rejects_bad_lists(text: str) -> None:
    with pytest.raises(ValueError):
        parse_counts(text)


def test_find_runs_prefers_best_and_orders_like_the_table(tmp_path) -> None:
    for name, ck in (("imu4_press", "best.pt"), ("imu4_press", "last.pt"),
                     ("imu2_nopress", "last.pt"), ("other", "best.pt")):  # fmt: skip
        (tmp_path / name).mkdir(exist_ok=True)
        (tmp_path / name / ck).write_bytes(b"")
    runs = find_runs(tmp_path)
    assert [(s.name, p.name) for s, p in runs] == [("imu2_nopress", "last.pt"),
                                                   ("imu4_press", "best.pt")]  # fmt: skip
    m = dict(MPJPE_mm=1.0, PA_MPJPE_mm=2.0, PEL_MPJPE_mm=3.0, MPJRE_deg=4.0,
             leaf_vel_err_mps=0.5, frames=10)  # fmt: skip
    table = sweep_table([(s, m) for s, _ in runs])
    assert "| 2 | no | 1.0 | 2.0 | 3.0 | 4.00 | 0.500 | 10 |" in table
