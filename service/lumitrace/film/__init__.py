"""What the photons leave behind: batch tallies, the cube map, per-emitter accumulators,
the pull-push filter and the error estimates of the maps."""
