#!/usr/bin/env python3
"""CI's check of deploy/k8s/ (docs/cluster.md), without a Kubernetes cluster.

1. Validates every manifest against the Kubernetes OpenAPI schemas that the
   kubernetes-validate package ships (strict: unknown fields are errors), for the oldest
   version the files claim to support and the newest the package knows.
2. Checks what the schema cannot: the Job is Indexed, completions = parallelism =
   TRANSCODE_SHARD_COUNT, restartPolicy Never, the shared claim mounted, INPUT and OUT under
   the mount, both Jobs running `transcode sequence`, the collect Job with --collect.
3. With --run TRANSCODE_BIN: plays the pods on this machine, one after the other. Each pod's
   command is expanded as Kubernetes does ($(NAME) from the container's env), with
   JOB_COMPLETION_INDEX set as the Job controller sets it and the mount folder replaced by a
   temporary one holding a 6-frame sequence; the training args are replaced by small ones.
   Then checks sequence.json. The Slurm test (tests/slurm/run.sh) covers shards running at
   the same time; this covers the manifest's command and environment.

Usage: tests/k8s/check.py [--run TRANSCODE_BIN]
"""

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
JOB = REPO / "deploy" / "k8s" / "indexed-job.yaml"
COLLECT = REPO / "deploy" / "k8s" / "collect-job.yaml"
# backoffLimitPerIndex is in the API from 1.28 (alpha) and on by default from 1.29.
OLDEST = "1.29.0"
SMALL = ["--resolution", "64", "--iterations", "60"]


def load(path):
    return [d for d in yaml.safe_load_all(path.read_text()) if d is not None]


def validate_schema(docs_by_file):
    import kubernetes_validate

    versions = [OLDEST, kubernetes_validate.latest_version()]
    for path, docs in docs_by_file.items():
        for doc in docs:
            for version in versions:
                try:
                    kubernetes_validate.validate(doc, version, strict=True)
                except kubernetes_validate.ValidationError as e:
                    sys.exit(
                        f"{path.name}: {doc['kind']} {doc['metadata']['name']} is not valid "
                        f"for Kubernetes {version}: {e.message} at {list(e.path)}"
                    )
    print(f"schema: {', '.join(p.name for p in docs_by_file)} valid (strict) for Kubernetes "
          f"{' and '.join(versions)} (kubernetes-validate {kubernetes_validate.__version__})")


def one(docs, kind):
    found = [d for d in docs if d["kind"] == kind]
    assert len(found) == 1, f"expected one {kind}, found {len(found)}"
    return found[0]


def container_of(job):
    containers = job["spec"]["template"]["spec"]["containers"]
    assert len(containers) == 1, "the Job's pod should have one container"
    return containers[0]


def env_of(container):
    return {e["name"]: e for e in container.get("env", [])}


def mount_of(job, claim):
    """The container's mount path of the volume backed by `claim`."""
    pod = job["spec"]["template"]["spec"]
    volumes = [v["name"] for v in pod["volumes"]
               if v.get("persistentVolumeClaim", {}).get("claimName") == claim]
    assert len(volumes) == 1, f"{job['metadata']['name']}: no volume from the claim {claim}"
    mounts = [m["mountPath"] for m in container_of(job)["volumeMounts"] if m["name"] == volumes[0]]
    assert len(mounts) == 1, f"{job['metadata']['name']}: the claim's volume is not mounted"
    return mounts[0]


def check_structure(job_docs, collect_docs):
    claim = one(job_docs, "PersistentVolumeClaim")
    assert "ReadWriteMany" in claim["spec"]["accessModes"], \
        "the claim must be ReadWriteMany: pods on several nodes write into it"
    job = one(job_docs, "Job")
    spec = job["spec"]
    assert spec["completionMode"] == "Indexed", "completionMode must be Indexed"
    count = spec["completions"]
    assert spec["parallelism"] == count, \
        f"parallelism {spec['parallelism']} differs from completions {count}"
    c = container_of(job)
    env = env_of(c)
    assert env["TRANSCODE_SHARD_COUNT"]["value"] == str(count), \
        f"TRANSCODE_SHARD_COUNT={env['TRANSCODE_SHARD_COUNT']['value']} but completions={count}"
    assert "JOB_COMPLETION_INDEX" not in env, \
        "JOB_COMPLETION_INDEX is the Job controller's to set"
    pod = spec["template"]["spec"]
    assert pod["restartPolicy"] == "Never", \
        "restartPolicy must be Never (backoffLimitPerIndex and podFailurePolicy need it)"
    assert spec.get("backoffLimitPerIndex", 0) >= 1, "backoffLimitPerIndex should allow a retry"
    for key in ("requests", "limits"):
        assert {"cpu", "memory"} <= set(c["resources"][key]), f"resources.{key} needs cpu and memory"
    rayon = env["RAYON_NUM_THREADS"]["valueFrom"]["resourceFieldRef"]
    assert rayon["resource"] == "limits.cpu", "RAYON_NUM_THREADS should follow the CPU limit"
    assert c["image"], "no image"
    mount = mount_of(job, claim["metadata"]["name"])
    for name in ("INPUT", "OUT"):
        assert env[name]["value"].startswith(mount + "/"), \
            f"{name}={env[name]['value']} is not on the shared volume at {mount}"
    assert c["command"][:2] == ["transcode", "sequence"], c["command"]
    assert "--shard" not in c["command"] + c.get("args", []), \
        "--shard would override the index Kubernetes gives each pod"

    collect = one(collect_docs, "Job")
    cc = container_of(collect)
    assert collect["spec"].get("completionMode", "NonIndexed") == "NonIndexed"
    assert collect["spec"]["completions"] == 1
    assert cc["command"][:2] == ["transcode", "sequence"] and "--collect" in cc["command"]
    assert mount_of(collect, claim["metadata"]["name"]) == mount
    cenv = env_of(cc)
    for name in ("INPUT", "OUT"):
        assert cenv[name]["value"] == env[name]["value"], \
            f"the collect Job's {name} differs from the Indexed Job's"
    assert cc["image"] == c["image"], "the collect Job's image differs from the Indexed Job's"
    print(f"structure: Indexed Job of {count} shards, TRANSCODE_SHARD_COUNT={count}, "
          f"claim {claim['metadata']['name']} at {mount}, collect Job alike")
    return job, collect, mount


def expand(text, env):
    """Kubernetes' $(NAME) expansion in command and args: defined names only, $$ escapes."""
    return re.sub(r"\$\$|\$\(([A-Za-z_][A-Za-z0-9_]*)\)",
                  lambda m: "$" if m.group(0) == "$$" else env.get(m.group(1), m.group(0)),
                  text)


def pod_command(job, mount, data, transcode, index, small):
    c = container_of(job)
    env = {}
    for name, e in env_of(c).items():
        if "value" in e:
            # Paths under the mount become paths under the stand-in folder.
            value = e["value"]
            env[name] = str(data) + value[len(mount):] if value.startswith(mount + "/") else value
        elif name == "RAYON_NUM_THREADS":
            env[name] = "1"
    if index is not None:
        env["JOB_COMPLETION_INDEX"] = str(index)
    command = [expand(a, env) for a in c["command"]]
    args = small if small is not None else [expand(a, env) for a in c.get("args", [])]
    assert command[0] == "transcode"
    return [str(transcode)] + command[1:] + args, env


def play(job, collect, mount, transcode):
    count = job["spec"]["completions"]
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "data"
        frames_rel = env_of(container_of(job))["INPUT"]["value"][len(mount) + 1:]
        frames = data / frames_rel
        subprocess.run([str(transcode), "synth", "--mesh",
                        str(REPO / "testdata/meshes/spider/spider.obj"), "--out", str(frames),
                        "--frames", "6", "--points", "20000", "--grid", "100",
                        "--cameras", "13"], check=True)
        # No variable of a Slurm job may leak in and pick the shard instead.
        base = {k: v for k, v in os.environ.items()
                if not k.startswith("SLURM_") and k not in ("JOB_COMPLETION_INDEX",
                                                            "TRANSCODE_SHARD_COUNT")}
        for index in range(count):
            argv, env = pod_command(job, mount, data, transcode, index, SMALL)
            print(f"pod {index}: {' '.join(argv)}", flush=True)
            subprocess.run(argv + ["--quiet"], env={**base, **env}, check=True)
        out = Path(pod_command(job, mount, data, transcode, None, SMALL)[1]["OUT"])
        m = json.loads((out / "sequence.json").read_text())
        names = sorted(p.stem for p in frames.glob("*.ply"))
        assert [f["name"] for f in m["frames"]] == names, m["frames"]
        assert all(f["state"] == "finished" for f in m["frames"]), m["frames"]
        assert m["summary"]["finished"] == 6, m["summary"]
        shards = [f["shard"] for f in m["frames"]]
        assert all(s["count"] == count for s in shards), shards
        assert [s["index"] for s in shards] == sorted(s["index"] for s in shards)
        assert {s["index"] for s in shards} == set(range(count)), shards
        for index in range(count):
            assert (out / "shards" / f"shard-{index}-of-{count}.json").is_file()
        (out / "sequence.json").unlink()
        (out / "sequence.html").unlink()
        argv, env = pod_command(collect, mount, data, transcode, None, [])
        print(f"collect pod: {' '.join(argv)}", flush=True)
        subprocess.run(argv + ["--quiet"], env={**base, **env}, check=True)
        assert (out / "sequence.json").is_file() and (out / "sequence.html").is_file()
        print(f"pods: {count} shards wrote 6 frames in blocks "
              f"{[s['index'] for s in shards]}; the collect pod merged them again")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--run", metavar="TRANSCODE_BIN", type=Path,
                        help="also play the pods with this transcode binary")
    args = parser.parse_args()
    job_docs, collect_docs = load(JOB), load(COLLECT)
    validate_schema({JOB: job_docs, COLLECT: collect_docs})
    job, collect, mount = check_structure(job_docs, collect_docs)
    if args.run:
        play(job, collect, mount, args.run.resolve())


if __name__ == "__main__":
    main()
