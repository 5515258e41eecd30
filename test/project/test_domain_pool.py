"""The test ROS domains (test/support/domains.py) are never all held by one
worker: with the documented minimum of 10 (``WINDER_TEST_DOMAINS``) and the
4 workers of ``make test``, each worker makes its session bags and still
finds a domain for its next test; and a test that keeps a domain past its
end fails, naming itself (conftest), so no holder can creep back.

Each case runs in processes of its own, on a pool of lock files in a temp
directory of their own (``TMPDIR``): another pytest run of the machine never
sees them. No node starts and nothing talks DDS: a stand-in ``winder`` makes
each bag, since the subject is who holds a domain, not what runs on it."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

from support import wait
from support.paths import ROOT

from winder.procs import popen

TEST_DIR = ROOT / "test"
WORKERS = 4  # make test's
POOL = "10-19"  # docs/DEVELOPING.md's minimum

#: ``winder run`` as the session bags call it, without ROS: its bag made a moment
#: later, and the exit status of the configuration (the --bag-dir's name) the
#: session expects (support.bags.STATUS, handed down by the worker)
STAND_IN = textwrap.dedent(
    """
    import json, os, sys, time
    from pathlib import Path

    bag_dir = Path(sys.argv[sys.argv.index("--bag-dir") + 1])
    time.sleep(0.3)
    (bag_dir / "run").mkdir(parents=True)
    sys.exit(json.loads(os.environ["STAND_IN_STATUS"]).get(bag_dir.name, 0))
    """
)

#: one pytest worker: every session bag, each followed by a test that takes a
#: domain of its own; then what this worker still holds
WORKER = textwrap.dedent(
    """
    import json, os, sys
    from pathlib import Path

    from support import bags, domains

    bags.BIN = Path(sys.argv[2])  # the stand-in winder
    os.environ["STAND_IN_STATUS"] = json.dumps(bags.STATUS)
    # a domain handed back rests 12 s (a killed node's DDS lease): nothing runs on these
    # domains, and the rest would only slow this case down
    domains.QUIET_S = 0.2
    session = bags.SessionBags(Path(sys.argv[1]))
    for name in bags.CONFIGS:
        session.get(name)
        domains.release_domain(domains.next_domain(timeout=60))  # the next test, on a domain of its own
    print("held at the end:", sorted(domains._held), flush=True)
    session.close()
    """
)


def _env(tmp_path: Path) -> dict[str, str]:
    locks = tmp_path / "locks"
    locks.mkdir(exist_ok=True)
    return {**os.environ, "TMPDIR": str(locks), "WINDER_TEST_DOMAINS": POOL, "PYTHONPATH": str(TEST_DIR)}


def test_four_workers_make_their_session_bags_on_the_minimum_pool(tmp_path: Path) -> None:
    """Four workers on 10 domains, each making all the session bags (9, three
    at a time) with a test's domain taken after each: all finish, holding
    nothing. Before, each run's domain was held to the session's end: the
    first worker held 9 of the 10, and the others waited for a free domain
    until they failed."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    winder = bin_dir / "winder"
    winder.write_text(f"#!{sys.executable}\n{STAND_IN}")
    winder.chmod(0o755)
    workers = []
    for i in range(WORKERS):
        root = tmp_path / f"worker{i}"
        root.mkdir()
        out = (tmp_path / f"worker{i}.log").open("w")
        with out:
            workers.append(
                popen(
                    [sys.executable, "-c", WORKER, str(root), str(bin_dir)],
                    env=_env(tmp_path),
                    stdin=subprocess.DEVNULL,
                    stdout=out,
                    stderr=subprocess.STDOUT,
                )
            )
    try:
        for i, p in enumerate(workers):
            # 9 runs of 0.3 s, 3 at a time, and 9 domains taken: seconds; next_domain waits 60 s
            code = wait.until_exit(p, 150, f"worker {i}")
            log = (tmp_path / f"worker{i}.log").read_text()
            assert code == 0, log
            assert "held at the end: []" in log, log
    finally:
        for p in workers:
            if p.poll() is None:
                p.kill()
                p.wait()


#: a test module that breaks the rule, as a new one could
LEAKY = textwrap.dedent(
    """
    import pytest
    from support.domains import next_domain, release_domain

    pytestmark = pytest.mark.ros


    @pytest.fixture(scope="module")
    def two():  # a module fixture that keeps two domains for its tests
        a, b = next_domain(), next_domain()
        yield
        release_domain(a)
        release_domain(b)


    def test_keeps_one():
        next_domain()


    def test_hands_back():
        release_domain(next_domain())


    def test_beside_two(two):
        pass


    def test_beside_them_again(two):  # the module's last: its fixture ends with it
        pass
    """
)


def test_a_test_that_keeps_a_domain_fails_naming_itself(tmp_path: Path) -> None:
    """The suite's conftest on a module whose test keeps a domain and whose
    module fixture keeps two: each is an error at the teardown of the test
    after which they were still held, naming it; the domain the test kept is
    handed back (the next test passes); the tests that keep none pass."""
    (tmp_path / "test_leaky.py").write_text(LEAKY)
    (tmp_path / "pytest.ini").write_text("[pytest]\nmarkers = ros: starts nodes\n")
    pytest = [sys.executable, "-m", "pytest", "-p", "conftest", "-p", "no:cacheprovider", "-q"]
    r = subprocess.run(
        [*pytest, "test_leaky.py"],
        cwd=tmp_path,
        env=_env(tmp_path),
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
    )
    out = r.stdout + r.stderr
    assert r.returncode == 1 and "4 passed, 2 errors" in out, out
    kept = r"test_leaky.py::test_keeps_one left ROS domains held: \[1\d\] that it took, not handed back"
    assert "ERROR at teardown of test_keeps_one" in out and re.search(kept, out), out
    many = r"test_leaky.py::test_beside_two left ROS domains held: \{.*\} .* more than 1"
    assert "ERROR at teardown of test_beside_two" in out and re.search(many, out), out
