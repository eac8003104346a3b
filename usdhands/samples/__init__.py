"""Generated sample assets: a humanoid with full hands, a labelled gesture database with
ground-truth finger motion, a conversational clip, body-only copies, and a cup prop.

In-memory API (no files): :func:`usdhands.samples.gestures.gesture_database`,
:func:`~usdhands.samples.gestures.conversation_clip`, :func:`~usdhands.samples.gestures.body_only`,
:func:`~usdhands.samples.humanoid.humanoid_skeleton`. :mod:`usdhands.samples.generate`
writes them to files.
"""
