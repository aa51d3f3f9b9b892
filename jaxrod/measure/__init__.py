"""jaxrod.measure: observables of measured (or simulated) rod shapes.

``analysis.analyze`` reads frames, curvature and twist profiles, Wr, Tw and Lk from a centreline
and a line drawn on the rod's surface; ``profiles`` describes a periodic profile (symmetry order,
peaks); ``polyline_files`` reads the polylines. The modules load on first use: ``curves`` needs
``scipy.interpolate``, which ``import jaxrod`` does not pay for."""
