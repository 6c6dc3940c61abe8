# the submissions graded by these tests are students' files, not test modules;
# the hostile ones must never be imported into the test process
collect_ignore_glob = ["solutions/*.py", "hostile/*.py"]
