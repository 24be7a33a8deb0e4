"""Fitting a luminaire to a requirement: ``lumitrace fit``.

The parameters (:mod:`.parameters`) are numeric attributes of the stage, components of
them, points of a mesh's profile and variant sets; a candidate is their values authored in
a layer over the stage (:mod:`.candidates`). Each candidate is traced with the same seed
and photon indices (common random numbers, :mod:`.measure`), selectively where an edit
touches few photons, on threads, processes or a Dask cluster (:mod:`.pool`); its merit
(:mod:`.objective`) is the distance of its distribution from a target file (:mod:`.target`)
and of its figures from goals, with a standard error. CMA-ES from ``cma`` searches
(:mod:`.search`), the photons per candidate growing as it closes in; a journal
(:mod:`.journal`) lets an interrupted fit resume; the best is traced again to a stated
error and written as an edits layer with its files, ``fit.json`` and ``fit.html``
(:mod:`.report`).
"""
