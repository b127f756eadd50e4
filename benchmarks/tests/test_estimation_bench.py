"""benchmarks.estimation's summary of the next-motion prediction per optimizer."""
import pytest


def test_estimation_benchmark_summarises_each_optimizers_prediction():
    """benchmarks.estimation --prediction: per optimizer the median over types; CMA-ES's seeds first
    reduced to their median per type; a blow-up counts as inf, a failed step is left out."""
    from benchmarks.estimation import prediction_summary

    per = {"1": {"prediction": {"random_search": {"median_mm": 30.0}, "cmaes": {"median_mm": 10.0},
                                "cmaes_1": {"median_mm": 14.0}, "cmaes_2": {"blew_up": True, "median_mm": None},
                                "de": {"error": "no tracked tip"}}},
           "5": {"prediction": {"random_search": {"median_mm": 50.0}, "cmaes": {"median_mm": 20.0},
                                "de": {"median_mm": 8.0}}}}
    out = prediction_summary(per)
    assert out == {"random_search": 40.0, "cmaes": pytest.approx((14.0 + 20.0) / 2), "de": 8.0}
    assert prediction_summary({"1": {}}) == {"random_search": None, "cmaes": None, "de": None}
