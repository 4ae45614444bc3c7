"""``python tests/scripts/farm_main.py run JOB.yaml``: the vecontact CLI with a test-only MPI thread
level (VECONTACT_TEST_THREAD_LEVEL, e.g. "serialized": the farm then runs without a coordinator thread)."""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.dirname(os.path.dirname(HERE)))

if __name__ == "__main__":
    if os.environ.get("VECONTACT_TEST_THREAD_LEVEL"):   # e.g. "serialized": no coordinator thread
        import mpi4py
        mpi4py.rc.thread_level = os.environ["VECONTACT_TEST_THREAD_LEVEL"]
    from vecontact.cli import main
    raise SystemExit(main(sys.argv[1:]))
