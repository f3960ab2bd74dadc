"""mlfe.distributed (python/mlfe/distributed.py): one volume's bricks on Dask workers give the
bytes of ``mlfe convert`` with the same options, on a LocalCluster and on a scheduler and two
workers started here as processes on 127.0.0.1; bad options raise before any task, workers'
errors come back as the local call's, a cancelled run leaves nothing. Run by ctest with
/usr/bin/python3 (tests/CMakeLists.txt): MLFE_BINARY is the command line."""
import json
import os
import subprocess
import tempfile
import time
import unittest

import distributed
import numcodecs
import numpy as np

import mlfe
import mlfe.distributed
from test_zarr import volume, write_store

BINARY = os.environ["MLFE_BINARY"]
ISO, BRICKS = 500, 8  # the blob of test_zarr.volume() (30 x 26 x 21) in 48 bricks


def write_raw(path, data_xyz, spacing=(0.75, 1.25, 3.0), origin=(2.5, -5.0, 10.0)):
    """A raw volume (x fastest) with its sidecar."""
    with open(path, "wb") as f:
        f.write(data_xyz.tobytes(order="F"))
    with open(path + ".json", "w") as f:
        json.dump({"dims": list(data_xyz.shape), "dtype": str(data_xyz.dtype), "endian": "little",
                   "spacing": list(spacing), "origin": list(origin)}, f)


class NoClient:
    """A client that fails the test when used: options must be refused before it is."""

    def __getattr__(self, name):
        raise AssertionError("the client was used (%s) before the options were checked" % name)


class DistributedTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory(prefix="mlfe_distributed_test_")
        self.dir = self.tmp.name
        self.raw = self.path("blob.raw")
        write_raw(self.raw, volume())

    def tearDown(self):
        self.tmp.cleanup()

    def path(self, name):
        return os.path.join(self.dir, name)

    def cli(self, src, name, *args):
        """`mlfe convert` of `src` in bricks: (exit status, stderr, the output's bytes or None)."""
        out = self.path(name)
        r = subprocess.run([BINARY, "convert", src, "--iso", str(ISO), "--bricks", str(BRICKS), *args, "-o", out],
                           capture_output=True, text=True)
        if not os.path.exists(out):
            return r.returncode, r.stderr, None
        with open(out, "rb") as f:
            return r.returncode, r.stderr, f.read()

    def distributed(self, src, name, client, **options):
        out = self.path(name)
        summary = mlfe.distributed.convert(src, out, client, iso=ISO, bricks=BRICKS, **options)
        with open(out, "rb") as f:
            return summary, f.read()

    def test_bytes_equal_the_command_line_on_a_local_cluster(self):
        store = self.path("blob.zarr")
        write_store(store, volume(), numcodecs.Blosc(cname="zstd"))
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cluster, distributed.Client(cluster) as client:
            seen = []
            summary, got = self.distributed(self.raw, "raw.glb", client,
                                            progress=lambda f, s: seen.append((f, s)))
            self.assertEqual(got, self.cli(self.raw, "raw_cli.glb")[2])
            self.assertGreater(summary["triangles"], 100)
            _, got = self.distributed(store, "zarr.glb", client, simplify=0.2, draco=False)
            self.assertEqual(got, self.cli(store, "zarr_cli.glb", "--simplify", "0.2", "--no-draco")[2])
        # Progress counts the bricks: 0 first, 0.9 when all are done, then writing up to 1.
        fractions = [f for f, _ in seen]
        self.assertEqual(fractions, sorted(fractions))
        self.assertEqual(seen[0], (0.0, "extracting"))
        self.assertEqual([s for f, s in seen if f == 0.9], ["extracting", "writing"])
        self.assertEqual(seen[-1], (1.0, "writing"))
        self.assertGreater(len(seen), 4)  # more than one group of bricks

    def test_scheduler_and_two_worker_processes(self):
        """A scheduler and two workers started as processes (dask-scheduler, dask-worker) on
        127.0.0.1: the command line's bytes; a worker's error raises as the local call's; all
        three processes end when the client shuts the cluster down."""
        scheduler_file = self.path("scheduler.json")
        common = ["--no-dashboard"]
        procs = [subprocess.Popen(["dask-scheduler", "--host", "127.0.0.1", "--port", "0", "--scheduler-file",
                                   scheduler_file, *common], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)]
        try:
            deadline = time.monotonic() + 60
            while not os.path.exists(scheduler_file) and time.monotonic() < deadline:
                time.sleep(0.1)
            for _ in range(2):
                procs.append(subprocess.Popen(
                    ["dask-worker", "--scheduler-file", scheduler_file, "--host", "127.0.0.1", "--nthreads", "1",
                     "--death-timeout", "30", *common], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE))
            with distributed.Client(scheduler_file=scheduler_file, timeout=60) as client:
                client.wait_for_workers(2, timeout=60)
                _, got = self.distributed(self.raw, "raw.glb", client)
                self.assertEqual(got, self.cli(self.raw, "raw_cli.glb")[2])
                # A NaN voxel inside one brick: the worker reading it fails as the command line does.
                data = volume().astype(np.float32)
                data[13, 11, 9] = np.nan
                nan = self.path("nan.raw")
                write_raw(nan, data)
                status, stderr, none = self.cli(nan, "nan_cli.glb")
                self.assertEqual((status, none), (2, None), stderr)
                with self.assertRaises(mlfe.Error) as e:
                    self.distributed(nan, "nan.glb", client)
                self.assertIs(type(e.exception), mlfe.Error)
                self.assertEqual("mlfe: " + str(e.exception), stderr.strip())
                self.assertFalse(os.path.exists(self.path("nan.glb")))
                client.shutdown()
            for p in procs:
                self.assertEqual(p.wait(timeout=60), 0, p.stderr.read().decode())
        finally:
            for p in procs:
                if p.poll() is None:
                    p.kill()
                    p.wait()
                p.stderr.close()

    def test_bad_options_raise_before_any_task(self):
        """Misspelt or invalid keywords, options that cannot be distributed and a missing file raise
        mlfe.Error on the client, with mlfe's message, before the client is used."""
        out = self.path("out.glb")
        cases = {
            "unknown option 'simplfy'": dict(iso=ISO, simplfy=0.2),
            "ratio: expected": dict(iso=ISO, ratio=2),
            "simplifier: ": dict(iso=ISO, simplifier="best"),
            "hierarchy: mlfe.distributed writes the asset alone": dict(iso=ISO, hierarchy=self.path("h.mlfeh")),
            "would be converted whole, not in bricks": dict(iso=ISO),  # auto: no bricks below 2^27 samples
            "lod": dict(iso=ISO, bricks=8, lod=2),
            "iso: required": dict(bricks=8),
        }
        for needle, options in cases.items():
            with self.subTest(needle), self.assertRaises(mlfe.Error) as e:
                mlfe.distributed.convert(self.raw, out, NoClient(), **options)
            self.assertIn(needle, str(e.exception))
        # A bad value gives the message mlfe.convert gives.
        with self.assertRaises(mlfe.Error) as local:
            mlfe.convert(self.raw, out, iso=ISO, ratio=2)
        with self.assertRaises(mlfe.Error) as remote:
            mlfe.distributed.convert(self.raw, out, NoClient(), iso=ISO, ratio=2)
        self.assertEqual(str(remote.exception), str(local.exception))
        # A missing file: the command line's message.
        missing = self.path("missing.raw")
        status, stderr, _ = self.cli(missing, "missing_cli.glb")
        self.assertEqual(status, 2)
        with self.assertRaises(mlfe.Error) as e:
            mlfe.distributed.convert(missing, out, NoClient(), iso=ISO, bricks=BRICKS)
        self.assertEqual("mlfe: " + str(e.exception), stderr.strip())
        self.assertEqual(sorted(os.listdir(self.dir)), ["blob.raw", "blob.raw.json"])

    def test_cancel_leaves_no_output(self):
        """progress returning False once bricks are done cancels: mlfe.Cancelled, no file; an
        exception raised by the callback is raised as it is (a LocalCluster made by the call)."""
        out = self.path("out.glb")

        def stop_after_bricks(fraction, stage):
            return fraction == 0.0

        with self.assertRaises(mlfe.Cancelled):
            mlfe.distributed.convert(self.raw, out, iso=ISO, bricks=BRICKS, n_workers=1, progress=stop_after_bricks)

        def fail(fraction, stage):
            if stage == "writing":
                raise KeyError("stop")

        with self.assertRaises(KeyError):
            mlfe.distributed.convert(self.raw, out, iso=ISO, bricks=BRICKS, n_workers=1, progress=fail)
        self.assertEqual(sorted(os.listdir(self.dir)), ["blob.raw", "blob.raw.json"])


if __name__ == "__main__":
    unittest.main()
