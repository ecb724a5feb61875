"""Analyses of the model: the work-precision report, the stability suite and the reference
scenarios the estimators are scored on."""
