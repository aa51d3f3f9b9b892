"""The scene constructors share one argument convention: the shape is positional (a knot's name,
a torus knot's (p, q), a closed curve's points), every quantity after it is keyword-only, and the
node count is called N."""
import inspect

import pytest

import jaxrod as jr

# each public constructor and the parameters that give its shape (positional)
SHAPE = {
    "ring": (),
    "michell_ring": (),
    "knot": ("name",),
    "trefoil": (),
    "torus_knot": ("p", "q"),
    "clamped_rod": (),
    "free_rod": (),
    "closed_curve": ("points",),
}
POSITIONAL = (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)


def test_every_scene_constructor_is_listed():
    public = {name for name in dir(jr) if not name.startswith("_")}
    scene_builders = {name for name in public
                      if callable(getattr(jr, name)) and getattr(getattr(jr, name), "__module__", "") ==
                      "jaxrod.model.scenes" and not name[0].isupper()
                      and not name.endswith(("critical_twist", "_energy"))}  # analytic references, not scenes
    assert scene_builders == set(SHAPE)


@pytest.mark.parametrize("name", sorted(SHAPE))
def test_shape_positional_quantities_keyword_only(name):
    params = list(inspect.signature(getattr(jr, name)).parameters.values())
    shape = SHAPE[name]
    assert tuple(p.name for p in params[:len(shape)]) == shape
    assert all(p.kind in POSITIONAL for p in params[:len(shape)])
    rest = params[len(shape):]
    assert rest and all(p.kind == inspect.Parameter.KEYWORD_ONLY for p in rest), \
        [(p.name, p.kind.name) for p in rest]
    assert "N" in {p.name for p in rest}


def test_a_positional_quantity_is_refused():
    with pytest.raises(TypeError):
        jr.michell_ring(24)
    with pytest.raises(TypeError):
        jr.knot("3_1", 61, D=8.0, L=292.0)
    assert jr.michell_ring(N=24).n_nodes == 24
