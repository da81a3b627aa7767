"""Post-processing that reads only the results file.

``vtk_series.export_vtk`` (.vtu + .pvd time series), ``render.render_model`` (offscreen PNG),
``plots.plot_history`` / ``plots.crack_map`` (curves and crack maps), ``views.damage_view`` /
``views.write_views`` (3-D damage views), ``animation.animate`` (GIF or MP4 of a run, also
``dr_masonry.viz.animate``) and ``report.write_report`` (the HTML run report).
"""


def __getattr__(name):
    """``animate``: :func:`dr_masonry.viz.animation.animate`, imported when first asked for (the
    package itself imports neither VTK nor matplotlib)."""
    if name == "animate":
        from .animation import animate
        return animate
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
