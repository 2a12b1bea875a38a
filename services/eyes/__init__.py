"""Eyes: the eyes driver (gaze, pupils, lids) and the web eye renderer."""
