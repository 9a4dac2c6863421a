"""`facette bench size --dask`: the `--memory` run's bands on a dask.distributed LocalCluster of 2
worker processes x 1 thread (the child process `bench.size` starts), one worker killed mid-run with
`--kill-worker`, and the table of those runs."""
import json
import os
import time

__all__ = ["dask_child", "print_dask"]


def _killer(client, after_s, said):
    """After `after_s` seconds, SIGKILL the first worker that holds tasks (checked every 0.2 s while
    none does); `said` gets the time, the tasks it held and their names' prefixes."""
    import signal
    import threading

    from dask.utils import key_split

    def kill():
        t0 = time.perf_counter()
        time.sleep(after_s)
        while not said.get("done"):
            held = {addr: keys for addr, keys in client.processing().items() if keys}
            if held:
                addr = max(held, key=lambda a: len(held[a]))
                pid = client.run(os.getpid, workers=[addr])[addr]
                os.kill(pid, signal.SIGKILL)
                said.update(at_s=time.perf_counter() - t0, lost=len(held[addr]),
                            tasks=sorted({key_split(k) for k in held[addr]}))
                return
            time.sleep(0.2)
    thread = threading.Thread(target=kill, daemon=True)
    thread.start()
    return thread


def dask_child(source, out, memory, method, kill_after):
    """`process --memory` of `source` (a scan or a folder) with its bands on a LocalCluster of 2
    workers x 1 thread; prints a JSON line: seconds, bands, the workers' max RSS (GB), killed (a
    worker was), kill_s (when) and lost (the tasks it held)."""
    import resource

    from dask.distributed import Client, LocalCluster

    from facette.pipeline import process
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, \
            Client(cluster) as client:
        pids = sorted(client.run(os.getpid).values())
        said = {}
        t0 = time.perf_counter()
        if kill_after > 0:
            _killer(client, kill_after, said)
        res = process(source, outputs=["normals", "height"], out_dir=out, method=method, memory=memory,
                      channels="green", scheduler=cluster.scheduler_address, overwrite=True)
        seconds = time.perf_counter() - t0
        said["done"] = True
        rss = client.run(lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6)
        after = sorted(client.run(os.getpid).values())
    print(json.dumps({"seconds": seconds, "bands": res.ps.info["tiles"], "workers_gb": sorted(rss.values()),
                      "killed": pids != after, "kill_s": said.get("at_s"), "lost": said.get("lost", 0),
                      "lost_tasks": said.get("tasks", [])}))


def print_dask(rows, what):
    dask = [r for r in rows if "dask_s" in r]
    if not dask:
        return
    print(f"the {what} on a dask.distributed LocalCluster (2 worker processes x 1 thread); GB: the largest "
          "process of the run's tree (wait4), worker GB: the workers' own largest; kill s: when a worker was "
          "killed, lost: the tasks it held; max°, px, height: against the untiled run, or (ref --memory) the "
          "--memory run without a cluster")
    print(f"{'size':>12} | {'dask s':>7} {'s/MP':>5} {'GB':>5} {'worker GB':>9} {'killed':>6} | {'max°':>8} "
          f"{'px > 0.01°':>10} {'height/range':>12} | {'ref':>8} {'kill s':>7} {'lost':>4} {'tasks':>8}")
    for r in dask:
        print(f"{r['size']:>12} | {r['dask_s']:7.1f} {r['dask_s'] / r['mp']:5.2f} {r['dask_gb']:5.2f} "
              f"{r['dask_workers_gb']:9.2f} {str(r['dask_killed']):>6} | {r['dask_deg']:8.5f} {r['dask_over']:10d} "
              f"{r['dask_height']:12.2e} | {r['dask_ref']:>8} {r['dask_kill_s']:7.1f} {r['dask_lost']:4d} "
              f"{r['dask_lost_tasks']:>8}", flush=True)
