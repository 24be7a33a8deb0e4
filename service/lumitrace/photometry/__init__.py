"""Type C photometry from the intensity map: the C-gamma grid, derived figures, IES LM-63
and EULUMDAT files, and the pictures lighting designers read (polar curve, solid)."""
