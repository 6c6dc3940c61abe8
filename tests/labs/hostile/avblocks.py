"""A file named avblocks.py in the class folder (also graded, and failing).

expect: loading the file: your code raised SystemExit: avblocks.py was imported
"""

raise SystemExit("avblocks.py was imported")
