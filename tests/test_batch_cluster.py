"""The Ray engine on two Ray nodes (``ray.cluster_utils.Cluster``, one CPU each, on this machine): the
tasks land on both nodes and every result equals a single fit. Skipped when Ray is not installed."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ray = pytest.importorskip("ray", reason="Ray not installed (pip install '.[ray]')")
cluster_utils = pytest.importorskip("ray.cluster_utils")

import rtloop
import test_batch as tb
from rtloop.batch import jobs
from rtloop.batch.on_ray import run_ray

photos = tb.photos  # the fixture: a 32x24 scene and three photos of it


@pytest.fixture(scope="module")
def two_nodes():
    saved = os.environ.get("PYTHONPATH")
    here = str(Path(rtloop.__file__).resolve().parents[1])  # the workers import the rtloop this test did
    os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (here, saved) if p)
    if ray.is_initialized():
        ray.shutdown()
    cluster = cluster_utils.Cluster(initialize_head=True, head_node_args={"num_cpus": 1,
                                                                          "include_dashboard": False})
    cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="warning", log_to_driver=False)
    yield cluster
    ray.shutdown()
    cluster.shutdown()
    if saved is None:
        del os.environ["PYTHONPATH"]
    else:
        os.environ["PYTHONPATH"] = saved


def test_tasks_spread_over_two_nodes_and_equal_single_fits(two_nodes, photos, tmp_path):
    scene, paths = photos
    assert len([n for n in ray.nodes() if n["Alive"]]) == 2 and ray.cluster_resources()["CPU"] == 2
    where = tmp_path / "where"
    where.mkdir()

    def noting_the_node(job, digest, threads, kwargs):  # pickled by value into the workers
        import ray as ray_in_worker

        from rtloop.batch.on_ray import _task

        node = ray_in_worker.get_runtime_context().get_node_id()
        (where / job["id"]).write_text(node, encoding="utf-8")
        return _task(job, digest, threads, kwargs)

    # a worker started on each node first (its start takes longer than a few fits of this tiny scene)
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    warm = ray.remote(lambda: __import__("rtloop") and None)
    ray.get([warm.options(scheduling_strategy=NodeAffinitySchedulingStrategy(n["NodeID"], soft=False)).remote()
             for n in ray.nodes() if n["Alive"]])
    batch = [{"id": f"n{i}", "scene": str(scene), "photo": str(paths[i % 3]), "seed": i % 2} for i in range(80)]
    todo = [(j, jobs.job_hash(j)) for j in jobs.jobs_from(batch)]
    out = tmp_path / "out"
    results = {r.id: r for r in run_ray(todo, address=None, threads=1, max_retries=1, task=noting_the_node,
                                        options={}, out=out, images=False, final_scale=1, final_spp=1)}
    assert sorted(results) == sorted(j["id"] for j in batch)
    ran = [p.read_text(encoding="utf-8") for p in where.iterdir()]
    nodes = set(ran)
    assert nodes == {n["NodeID"] for n in ray.nodes() if n["Alive"]}  # both nodes ran jobs
    want = {(k, s): tb.single(scene, paths[k], s) for k in range(3) for s in range(2)}
    for r in results.values():
        i = int(r.id[1:])
        assert r.ok and r.x == want[(i % 3, i % 2)].x and r.products == want[(i % 3, i % 2)].products, r.id
        assert (out / r.id / "result.json").is_file()
