"""Write the small bad-model ONNX fixtures used by tests/detector (needs the onnx package).

    /work/venv-train/bin/python -m training.make_fixtures tests/detector/fixtures
"""

from __future__ import annotations

import sys
from pathlib import Path

import onnx
from onnx import TensorProto, helper


def _identity_model(shape: list[int], opset: int) -> onnx.ModelProto:
    """A one-node graph (Relu) with the given input shape and opset."""
    x = helper.make_tensor_value_info("images", TensorProto.FLOAT, shape)
    y = helper.make_tensor_value_info("out", TensorProto.FLOAT, shape)
    graph = helper.make_graph([helper.make_node("Relu", ["images"], ["out"])], "g", [x], [y])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)])
    model.ir_version = 10
    return model


def main(folder: Path) -> None:
    """Write wrong_input_shape.onnx (1x1x64x50 input) and opset_too_high.onnx (opset 99)."""
    folder.mkdir(parents=True, exist_ok=True)
    onnx.save(_identity_model([1, 1, 64, 50], 17), str(folder / "wrong_input_shape.onnx"))
    onnx.save(_identity_model([1, 3, 416, 416], 99), str(folder / "opset_too_high.onnx"))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
