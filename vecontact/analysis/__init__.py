"""Post-processing of results files.

- :mod:`~vecontact.analysis.morphology`: contact-map statistics (patches, perimeter, anisotropy);
- :mod:`~vecontact.analysis.study`: a results file read for analysis (job, theory per q1, /cases);
- :mod:`~vecontact.analysis.ensemble`: seed averages with standard errors (converged cases only);
- :mod:`~vecontact.analysis.curves`: master-curve fit and scatter, small-load slope, peaks, interpolation;
- :mod:`~vecontact.analysis.paper`, :mod:`~vecontact.analysis.beyond`, :mod:`~vecontact.analysis.sweep`:
  the numbers of the paper-reproduction report as tables (:mod:`~vecontact.analysis.tables`), written by
  :mod:`~vecontact.analysis.report` (``vecontact report``).
"""
