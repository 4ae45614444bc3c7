"""``python tests/scripts/farm_main.py run JOB.yaml``: the vecontact CLI, with the farm tests' stand-in
solver installed when the real one is not importable (or VECONTACT_FARM_STANDIN=1)."""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.dirname(os.path.dirname(HERE)))

import farm_standin  # noqa: E402

if __name__ == "__main__":
    if os.environ.get("VECONTACT_TEST_THREAD_LEVEL"):   # e.g. "serialized": no coordinator thread
        import mpi4py
        mpi4py.rc.thread_level = os.environ["VECONTACT_TEST_THREAD_LEVEL"]
    farm_standin.install(force=os.environ.get("VECONTACT_FARM_STANDIN") == "1")
    from vecontact.cli import main
    raise SystemExit(main(sys.argv[1:]))
