"""Camera: frame capture and the BlazeFace face detector."""
