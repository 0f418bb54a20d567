"""MCA tests (a package: its test_drives.py and tests/md/test_drives.py share a file name)."""
