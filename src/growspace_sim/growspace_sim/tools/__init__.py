"""The console programs, thin over the library: ``growspace-demo`` (``demo``), ``teleop``,
``growspace-record`` (``record``), ``growspace-bench`` (``bench``), ``growspace-eval``
(``evaluate``) and ``pub`` (a one-shot publisher for machines without the ``ros2`` CLI).
"""
