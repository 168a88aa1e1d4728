"""Analysis of rod packings: local fields, the average crossing number, statistics, figures.

>>> from rodwarp import analysis
>>> fields = analysis.compute_fields(rods)                 # phi, S, c, e, n, ... on a grid  # doctest: +SKIP
>>> stats = analysis.field_statistics(fields)              # means, cv_e, e_lb, tangles      # doctest: +SKIP
>>> analysis.linking_number(a, b)                          # exact Gauss integral            # doctest: +SKIP
>>> analysis.analyze("runs/alpha100_freq10_g0.5_seed0")   # what `rodwarp analyze` does      # doctest: +SKIP

One private module per job, their public names re-exported here (scikit-image's layout):

=================  ==========================================================================
``_registry``      the field registry: one :class:`FieldSpec` row per field (:data:`FIELDS`)
``_fields``        :func:`compute_fields` - the Warp passes of :mod:`rodwarp.kernels.fields`
``_fieldset``      :class:`Fields` - the container and ``fields.zarr``
``_acn``           :func:`gauss_linking`, :func:`linking_number`, :func:`average_crossing_number`
``_stats``         :func:`field_statistics`, :func:`outlier_bound`, :func:`find_tangles`, ...
``_tail``          :func:`tail_fit` - is the upper tail a power law? (Clauset et al. 2009)
``_regions``       :func:`packing_regions` - a packing's core and rim; :func:`pair_entanglement`
``_figures``       :func:`plot_histograms`, :func:`plot_slices`, :func:`plot_zprofiles`, ...
``_analyze``       :func:`analyze` - the ``rodwarp analyze`` pipeline, input to files
``_checks``        :func:`check_analyze` - the command's options, before any work
=================  ==========================================================================

Definitions, the exact clipping, the outlier bound and what the authors' field code got wrong
are in ``docs/fields.md``.  Names load on first use, so importing this package stays cheap
(no Warp, no matplotlib) until a function needs them.
"""

from rodwarp._util import lazy_exports

_WHERE = {
    # the registry (no Warp)
    "FieldSpec": "_registry", "BallMeasures": "_registry", "FIELDS": "_registry", "field_names": "_registry",
    "field_spec": "_registry", "fields_with": "_registry", "fields_help": "_registry",
    # fields
    "Fields": "_fieldset",
    "compute_fields": "_fields", "resolve_params": "_fields", "grid_axes": "_fields", "inside_mask": "_fields",
    "resolve_contacts": "_fields", "FieldParams": "_fields",
    # average crossing number
    "gauss_linking": "_acn", "linking_number": "_acn", "average_crossing_number": "_acn",
    # statistics
    "field_statistics": "_stats", "outlier_bound": "_stats", "find_tangles": "_stats", "histogram": "_stats",
    "power_law_fit": "_stats", "power_law_density": "_stats", "log_histogram": "_stats",
    "z_profiles": "_stats",
    "tail_fit": "_tail", "TailFit": "_tail",
    "packing_regions": "_regions", "PackingRegions": "_regions", "pair_entanglement": "_regions",
    # figures
    "plot_histograms": "_figures", "plot_slices": "_figures", "plot_zprofiles": "_figures",
    "plot_tangles": "_figures",
    # the pipeline
    "analyze": "_analyze", "AnalyzeOptions": "_analyze", "load_input": "_analyze", "default_out": "_analyze",
    "check_analyze": "_checks", "check_grid_memory": "_checks",
}

__all__ = sorted(_WHERE)
__getattr__, __dir__ = lazy_exports(__name__, _WHERE)
