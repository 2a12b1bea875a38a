"""Audio: the play_sound action and the audio player."""
