"""Photon paths: counter-based random streams, sampling, emission, scattering and the
wavefront tracer that fills a batch's tally from one batch job."""
