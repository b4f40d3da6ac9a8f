"""Pareto front of run-time/accuracy trade-offs."""

from dpi.studies.pareto import pareto_front


def test_pareto_front_known_answer():
    rows = [{"s": 1, "psnr": 20}, {"s": 2, "psnr": 25}, {"s": 3, "psnr": 24}, {"s": 1, "psnr": 19},
            {"s": 5, "psnr": 30}]
    assert pareto_front(rows, minimize=("s",), maximize=("psnr",)) == [True, True, False, False, True]


def test_equal_rows_are_both_on_the_front():
    rows = [{"s": 1.0, "mse": 0.1}, {"s": 1.0, "mse": 0.1}]
    assert pareto_front(rows, minimize=("s", "mse"), maximize=()) == [True, True]
