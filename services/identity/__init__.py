"""Identity: who a face is, with consent (docs/identity.md).

Pure building blocks so far: `embedding.py` (aligned crop from the face
detector's keypoints -> unit vector), `matching.py` (a name only when the
best match is clear) and `gallery.py` (the consented names and embeddings,
one owner-only file). The identity service stage, enrolment verbs and the
greeting by name build on them.
"""
