"""jaxrod.model: the rod itself. Discrete-curve geometry (``geometry``), material (``material``),
energy terms as objects (``terms``, over the pure energy functions of ``energy`` and ``contact``),
scenes built from terms (``rods``: the scene classes; ``scenes``: their constructors; ``knots``:
knot point tables), the DOF layout (``layout``), the structured Hessian (``hessian``), writhe and
linking (``topology``), contact neighbourhoods (``neighbourhood``) and the two-fold symmetry of a
closed rod (``symmetry``)."""
