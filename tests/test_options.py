"""jaxparam.options: one vocabulary of option names, and defaults read from signatures."""
import numpy as np
import pytest

import jaxparam as jp
from jaxparam.errors import MeshError, PointCloudError
from jaxparam.options import canonical, choose, default_of, hyphenated

KINDS = ("uniform", "inverse_distance", "shape_preserving")


@pytest.mark.parametrize("given", ["shape_preserving", "shape-preserving"])
def test_choose_accepts_both_spellings(given):
    assert choose(given, KINDS, what="weights", where="convex_map") == "shape_preserving"


def test_choose_compares_against_hyphenated_choices_too():
    assert choose("inverse_distance", ("uniform", "inverse-distance"), what="weights",
                  where="x") == "inverse_distance"


def test_choose_names_function_option_value_and_choices():
    with pytest.raises(MeshError, match=r"^convex_map: unknown weights 'cot'; use one of uniform, "
                                        r"inverse_distance, shape_preserving\.$"):
        choose("cot", KINDS, what="weights", where="convex_map")


def test_choose_raises_the_given_class_and_refuses_non_strings():
    with pytest.raises(PointCloudError, match=r"meshless_map: unknown weights None"):
        choose(None, KINDS, what="weights", where="meshless_map", error=PointCloudError)
    with pytest.raises(MeshError, match=r"^unknown spacing 'even'"):      # no prefix when where=""
        choose("even", ("uniform", "chord"), what="spacing", where="")


def test_spellings():
    assert canonical("mean-value") == "mean_value" and hyphenated("mean_value") == "mean-value"
    assert canonical(hyphenated("clough_tocher")) == "clough_tocher"


def test_default_of_reads_the_signature():
    assert isinstance(default_of(jp.minimize, "max_iters"), int)
    assert default_of(jp.convex_map, "weights") == "shape_preserving"

    def f(a, *, b=3, **options):
        return a

    assert default_of(f, "b") == 3
    assert default_of(f, "c", fallback=7) == 7
    with pytest.raises(TypeError, match=r"has no parameter 'a' with a default"):
        default_of(f, "a")


def test_every_api_function_takes_both_spellings():
    """Issue 11 item 10: the hyphenated and the underscore name give the same result."""
    import jaxparam as jp

    m = jp.shapes.disk(4, seed=1, height=0.3)
    P = np.asarray(jp.shapes.graph_surface(8).vertices)
    pairs = [
        lambda s: jp.convex_map(m, weights=s("shape_preserving")),
        lambda s: jp.weights.entry_weights(m.vertices, m.topology, s("mean_value"))[0],
        lambda s: jp.meshless_map(P, weights=s("inverse_distance"))[0],
        lambda s: jp.fit_surface(m, jp.convex_map(m), kind=s("clough_tocher")).sample(5).vertices,
    ]
    for f in pairs:
        a, b = f(lambda n: n), f(lambda n: n.replace("_", "-"))
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
