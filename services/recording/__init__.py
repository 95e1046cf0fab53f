"""Deprecated: the recording library moved to `gngdt_io` (gngdt 0.2); `services.recording.reader`
and `services.recording.frame` forward there until the next release."""
