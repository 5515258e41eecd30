"""Analysis of recorded runs: winding accuracy and motion quality
(:mod:`~winder.analysis.metrics`), inertia and damping identification
(:mod:`~winder.analysis.identify`); plots in :mod:`winder.analysis.figures`
(the only part of the library importing matplotlib)."""
