"""A file named numpy.py in the class folder (also graded, and failing).

expect: loading the file: your code raised SystemExit: numpy.py was imported
"""

raise SystemExit("numpy.py was imported")
