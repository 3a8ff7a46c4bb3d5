"""Writes an FRMD demonstration file as a LeRobot dataset with pyarrow, the writer LeRobot itself
uses (through Hugging Face `datasets` in v2.1, directly in v3.0): fixed-size float32 list columns,
snappy compression, `meta/info.json`, the episodes and tasks metadata of each layout.

    python lerobot_writer.py DEMOS.safetensors OUT_DIR v2.1|v3.0

made the datasets of frmd-host/tests/data/lerobot/ (from `frmd collect --task reach --episodes 3
--seed 5`); the tests call `write()` on fresh demonstrations as well."""
import json
import os
import struct
import sys

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

DTYPES = {"F32": np.float32, "I64": np.int64}


def read_safetensors(path):
    """(tensors by name, metadata) of a safetensors file (the format is a JSON header + bytes)."""
    raw = open(path, "rb").read()
    (n,) = struct.unpack("<Q", raw[:8])
    header = json.loads(raw[8:8 + n])
    meta = header.pop("__metadata__", {})
    body = raw[8 + n:]
    tensors = {k: np.frombuffer(body[v["data_offsets"][0]:v["data_offsets"][1]], DTYPES[v["dtype"]]).reshape(v["shape"])
               for k, v in header.items()}
    return tensors, meta


def _vectors(values):
    return pa.FixedSizeListArray.from_arrays(pa.array(values.astype(np.float32).ravel()), values.shape[1])


def frames_table(obs, action, episode, first_index, fps):
    n = len(obs)
    return pa.table({
        "observation.state": _vectors(obs),
        "action": _vectors(action),
        "timestamp": pa.array((np.arange(n) / fps).astype(np.float32)),
        "frame_index": pa.array(np.arange(n, dtype=np.int64)),
        "episode_index": pa.array(np.full(n, episode, dtype=np.int64)),
        "index": pa.array(np.arange(first_index, first_index + n, dtype=np.int64)),
        "task_index": pa.array(np.zeros(n, dtype=np.int64)),
    })


def write(obs, action, episode_ends, fps, out, version, task="reach the goal"):
    """Writes episodes (rows of `obs`/`action` split at `episode_ends`) as a LeRobot dataset."""
    os.makedirs(os.path.join(out, "meta"), exist_ok=True)
    starts = np.concatenate([[0], episode_ends[:-1]]).astype(int)
    tables = [frames_table(obs[s:e], action[s:e], i, s, fps) for i, (s, e) in enumerate(zip(starts, episode_ends))]
    features = {
        "observation.state": {"dtype": "float32", "shape": [obs.shape[1]], "names": None},
        "action": {"dtype": "float32", "shape": [action.shape[1]], "names": None},
        "observation.images.front": {"dtype": "video", "shape": [96, 96, 3], "names": ["height", "width", "channels"]},
        "timestamp": {"dtype": "float32", "shape": [1], "names": None},
        "frame_index": {"dtype": "int64", "shape": [1], "names": None},
        "episode_index": {"dtype": "int64", "shape": [1], "names": None},
        "index": {"dtype": "int64", "shape": [1], "names": None},
        "task_index": {"dtype": "int64", "shape": [1], "names": None},
    }
    info = {"codebase_version": version, "robot_type": "frmd-reach", "total_episodes": len(tables),
            "total_frames": int(len(obs)), "total_tasks": 1, "chunks_size": 1000, "fps": fps,
            "splits": {"train": f"0:{len(tables)}"}, "features": features}
    lengths = [t.num_rows for t in tables]
    if version == "v2.1":
        info["data_path"] = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
        os.makedirs(os.path.join(out, "data", "chunk-000"), exist_ok=True)
        for i, t in enumerate(tables):
            pq.write_table(t, os.path.join(out, "data", "chunk-000", f"episode_{i:06d}.parquet"))
        with open(os.path.join(out, "meta", "episodes.jsonl"), "w") as f:
            for i, n in enumerate(lengths):
                f.write(json.dumps({"episode_index": i, "tasks": [task], "length": n}) + "\n")
        with open(os.path.join(out, "meta", "tasks.jsonl"), "w") as f:
            f.write(json.dumps({"task_index": 0, "task": task}) + "\n")
    elif version == "v3.0":
        info["data_path"] = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
        os.makedirs(os.path.join(out, "data", "chunk-000"), exist_ok=True)
        pq.write_table(pa.concat_tables(tables), os.path.join(out, "data", "chunk-000", "file-000.parquet"))
        os.makedirs(os.path.join(out, "meta", "episodes", "chunk-000"), exist_ok=True)
        ends = np.cumsum(lengths)
        pq.write_table(pa.table({
            "episode_index": pa.array(np.arange(len(lengths), dtype=np.int64)),
            "tasks": pa.array([[task]] * len(lengths)),
            "length": pa.array(np.array(lengths, dtype=np.int64)),
            "data/chunk_index": pa.array(np.zeros(len(lengths), dtype=np.int64)),
            "data/file_index": pa.array(np.zeros(len(lengths), dtype=np.int64)),
            "dataset_from_index": pa.array(ends - np.array(lengths)),
            "dataset_to_index": pa.array(ends),
        }), os.path.join(out, "meta", "episodes", "chunk-000", "file-000.parquet"))
        pq.write_table(pa.table({"task_index": pa.array([0], pa.int64()), "task": pa.array([task])}),
                       os.path.join(out, "meta", "tasks.parquet"))
    else:
        raise ValueError(f"version {version!r}: expected v2.1 or v3.0")
    with open(os.path.join(out, "meta", "info.json"), "w") as f:
        json.dump(info, f, indent=4)


def write_demos(demos_path, out, version):
    tensors, meta = read_safetensors(demos_path)
    fps = round(1.0 / float(meta["dt"]), 6)
    write(tensors["obs"], tensors["action"], tensors["episode_ends"], fps, out, version)


if __name__ == "__main__":
    write_demos(*sys.argv[1:4])
