"""A file named random.py in the class folder (also graded, and failing).

When the old grader ran inside the folder, its child (``python -c``) put
the folder first on ``sys.path``, so every submission's ``import random``
(NumPy's included) found this file and failed. The student's process now
runs ``python -I`` in its own empty folder.

expect: loading the file: your code raised SystemExit: random.py was imported
"""

raise SystemExit("random.py was imported")
