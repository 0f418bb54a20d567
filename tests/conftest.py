"""Marks the few longest tests ``slow``.

They run by default (``pytest``, the README's command, runs everything); ``pytest -m "not slow"``
leaves them out.  The list was measured once with ``pytest -n 2 --durations=25`` on two shared
cores (load about 4); the time beside each is that run's.  Listed here rather than decorated in
the test files, so that the list is one place; ``tests/test_slow_marker.py`` checks that every
entry names a test that exists.
"""

import pytest

#: (test file name, test name with its parameters if any) -> seconds in the measured run
SLOW = {
    ("test_calculator.py", "test_virial_pressure_equals_cold_curve[0.9]"): 83,
    ("test_fragments.py", "test_chain_ring_and_isolated_clusters_exact_spectrum"): 54,
    ("test_examples.py", "test_example_runs[profiles_from_file.py]"): 51,
    ("test_cli_contract.py", "test_ten_kinds_of_bad_input"): 49,
    ("test_calculator.py", "test_cache_sees_material_changes_and_computes_only_what_is_asked"): 33,
    ("test_docs_build.py", "test_docs_build_without_warnings"): 33,
    ("test_drives.py", "test_constant_table_gives_the_constant_pistons_run_bit_for_bit"): 31,
    ("test_fragments.py", "test_observer_records_counts_during_a_run_and_feeds_h5md"): 23,
}


def pytest_collection_modifyitems(config, items):
    for item in items:
        if (item.path.name, item.name) in SLOW:
            item.add_marker(pytest.mark.slow)
