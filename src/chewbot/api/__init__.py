"""The Python API: the verbs a dynamics user expects, as functions of a model and arrays (``chewbot.NAME``)."""
