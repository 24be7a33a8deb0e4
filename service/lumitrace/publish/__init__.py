"""Writing a result: the intensity EXR, IES/LDT files and pictures, the result layer,
and the order in which they appear on disk."""
