"""Runs an exported policy in onnxruntime (tests/export_onnx.rs).

    python tests/tools/run_onnx.py policy.onnx observations.json

observations.json is a list of rows (float32 observations). Prints one JSON object: the actions
for all rows at once and for the first row alone (the batch axis is dynamic), the input and
output names and shapes as onnxruntime reads them, and the model's custom metadata.
"""

import json
import sys

import numpy as np
import onnxruntime as ort

model, rows = sys.argv[1], sys.argv[2]
with open(rows) as f:
    obs = np.array(json.load(f), dtype=np.float32)
session = ort.InferenceSession(model, providers=["CPUExecutionProvider"])
(output,) = session.get_outputs()
(input_,) = session.get_inputs()
all_rows = session.run([output.name], {input_.name: obs})[0]
first_row = session.run([output.name], {input_.name: obs[:1]})[0]
meta = session.get_modelmeta()
print(
    json.dumps(
        {
            "actions": all_rows.astype(float).tolist(),
            "first_row": first_row.astype(float).tolist(),
            "input": [input_.name, input_.shape, input_.type],
            "output": [output.name, output.shape, output.type],
            "producer": meta.producer_name,
            "metadata": meta.custom_metadata_map,
            "onnxruntime": ort.__version__,
        }
    )
)
