"""Runs an exported model with several inputs in onnxruntime (tests/export_latent_onnx.rs).

    python tests/tools/run_onnx_feeds.py model.onnx feeds.json

feeds.json maps each input name to its rows (float32). Prints one JSON object: every output by
name, the inputs' and outputs' names and shapes as onnxruntime reads them, and the model's custom
metadata.
"""

import json
import sys

import numpy as np
import onnxruntime as ort

model, feeds_path = sys.argv[1], sys.argv[2]
with open(feeds_path) as f:
    feeds = {k: np.array(v, dtype=np.float32) for k, v in json.load(f).items()}
session = ort.InferenceSession(model, providers=["CPUExecutionProvider"])
names = [o.name for o in session.get_outputs()]
values = session.run(names, feeds)
meta = session.get_modelmeta()
print(
    json.dumps(
        {
            "outputs": {n: v.astype(float).tolist() for n, v in zip(names, values)},
            "inputs": [[i.name, i.shape] for i in session.get_inputs()],
            "output_shapes": [[o.name, o.shape] for o in session.get_outputs()],
            "metadata": meta.custom_metadata_map,
            "onnxruntime": ort.__version__,
        }
    )
)
