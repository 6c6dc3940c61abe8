"""Closing every file descriptor, the channel's included.

While loading, closes descriptors 0 to 99. The student's process can no
longer answer and ends; the grader reports that, and goes on.

expect: the process running your code ended
expect: while loading the file of lab 1
"""

import os

os.closerange(0, 100)
