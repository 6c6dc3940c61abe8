# the submissions graded by these tests are students' files, not test modules
collect_ignore_glob = ["solutions/*.py"]
