"""Process plumbing: a handler error is counted by exception type and printed once."""

from companion.runtime import count_handler_error


class _Msg:
    def get_type(self) -> str:
        return "HIGHRES_IMU"


def test_handler_errors_are_counted_by_type_and_printed_once(capsys):
    counters: dict[str, int] = {"imu_used": 3}
    for _ in range(3):
        count_handler_error(counters, "estimator", _Msg(), ValueError("bad"))
    count_handler_error(counters, "estimator", _Msg(), OverflowError("big"))
    assert counters == {"imu_used": 3, "handler_error_ValueError": 3, "handler_error_OverflowError": 1}
    err = capsys.readouterr().err.splitlines()
    assert err == [
        "estimator: HIGHRES_IMU raised ValueError: bad",
        "estimator: HIGHRES_IMU raised OverflowError: big",
    ]
