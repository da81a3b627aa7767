"""Post-processing that reads only the results file.

``vtk_series.export_vtk`` (.vtu + .pvd time series), ``render.render_model`` (offscreen PNG),
``plots.plot_history`` / ``plots.crack_map`` (curves and crack maps).
"""
