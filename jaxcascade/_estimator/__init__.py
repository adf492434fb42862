"""Estimator variants beyond the paper's literal iteration (`jaxcascade._estimate`)."""
