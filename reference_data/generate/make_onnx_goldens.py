"""Tiny ONNX models and their outputs from onnx.reference.ReferenceEvaluator (issue #7,
SPEC.md §19.4).

Each case folder reference_data/onnx/<case>/ holds model.onnx, card.json (unseen's model
card), the inputs as .npy (float32) and expected.npy, the evaluator's output. The models
use the operators Depth Anything / LaMa-style networks are made of: Conv, Instance- and
BatchNormalization, Relu/Sigmoid/Clip, Resize (linear half-pixel, linear align-corners,
nearest), Concat, Transpose, Add/Mul. Weights are seeded.

  depth_tiny      image [1,3,12,16] -> depth [1,1,24,32] (NCHW)
  inpaint_tiny    image [1,3,16,16] + mask [1,1,16,16] -> output [1,3,16,16]
  fixer_nhwc      image [1,10,14,3] -> out [1,10,14,3] (NHWC, residual)
  depth_e2e       the depth_tiny model behind its card on a 20x15 RGB image: cv2.resize
                  (INTER_LINEAR) to 16x12, ImageNet mean/std, the evaluator, cv2.resize back
                  to 20x15 -> expected.npy (15x20); tests the adapter's whole path
  resize_half     Resize(linear, half_pixel) x2 alone: tract 0.21 does not clamp the source
                  coordinate below 0, so the first output row/column extrapolates (the test
                  checks the interior and reports the edge)
  bad_rank        a model whose image input has rank 3 (the adapter must refuse it)

Run: python make_onnx_goldens.py
"""
import json
import os

import cv2
import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper
from onnx.reference import ReferenceEvaluator

HERE = os.path.dirname(__file__)
OUT = os.path.join(HERE, "..", "onnx")
OPSET = 17
rng = np.random.Generator(np.random.PCG64(17))


def init(name, arr):
    return numpy_helper.from_array(np.asarray(arr, np.float32), name)


def conv_w(cout, cin, k):
    return rng.normal(0, 0.4, (cout, cin, k, k)).astype(np.float32)


def save(case, model, card, inputs):
    d = os.path.join(OUT, case)
    os.makedirs(d, exist_ok=True)
    onnx.checker.check_model(model)
    onnx.save(model, os.path.join(d, "model.onnx"))
    with open(os.path.join(d, "card.json"), "w") as f:
        json.dump(card, f, indent=1)
    sess = ReferenceEvaluator(model)
    out = sess.run(None, inputs)[0].astype(np.float32)
    for k, v in inputs.items():
        np.save(os.path.join(d, f"input_{k}.npy"), v.astype(np.float32))
    np.save(os.path.join(d, "expected.npy"), out)
    print(case, {k: v.shape for k, v in inputs.items()}, "->", out.shape, flush=True)
    return sess


def depth_model():
    nodes = [
        helper.make_node("Conv", ["image", "w1", "b1"], ["c1"], pads=[1, 1, 1, 1]),
        helper.make_node("InstanceNormalization", ["c1", "g1", "be1"], ["n1"], epsilon=1e-5),
        helper.make_node("Relu", ["n1"], ["r1"]),
        helper.make_node("Resize", ["r1", "", "scales"], ["u1"], mode="linear",
                         coordinate_transformation_mode="align_corners"),
        helper.make_node("Conv", ["u1", "w2", "b2"], ["c2"]),
        helper.make_node("Resize", ["c2", "", "scales1"], ["u2"], mode="linear",
                         coordinate_transformation_mode="half_pixel"),
        helper.make_node("Relu", ["u2"], ["depth"]),
    ]
    inits = [init("w1", conv_w(4, 3, 3)), init("b1", rng.normal(0, 0.1, 4)),
             init("g1", rng.uniform(0.5, 1.5, 4)), init("be1", rng.normal(0, 0.2, 4)),
             init("scales", [1, 1, 2, 2]), init("w2", conv_w(1, 4, 1)), init("b2", [0.3]),
             init("scales1", [1, 1, 1, 1])]
    g = helper.make_graph(nodes, "depth_tiny",
                          [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, "h", "w"])],
                          [helper.make_tensor_value_info("depth", TensorProto.FLOAT, [1, 1, "h2", "w2"])], inits)
    return helper.make_model(g, opset_imports=[helper.make_opsetid("", OPSET)])


def main():
    # depth_tiny
    m = depth_model()
    card = dict(model="model.onnx", inputs=dict(image="image"), output="depth", layout="nchw",
                size=dict(policy="fixed", width=16, height=12), resize="bilinear",
                input_range=[0.0, 1.0], mean=[0.485, 0.456, 0.406], std=[0.229, 0.224, 0.225],
                output_kind="disparity")
    save("depth_tiny", m, card, dict(image=rng.normal(0, 1, (1, 3, 12, 16)).astype(np.float32)))

    # depth_e2e: the same model behind its card on an image
    img = rng.uniform(0, 1, (15, 20, 3)).astype(np.float32)
    small = cv2.resize(img, (16, 12), interpolation=cv2.INTER_LINEAR)
    x = ((small - np.array(card["mean"], np.float32)) / np.array(card["std"], np.float32))
    x = x.transpose(2, 0, 1)[None].astype(np.float32)
    y = ReferenceEvaluator(m).run(None, dict(image=x))[0][0, 0].astype(np.float32)
    back = cv2.resize(y, (20, 15), interpolation=cv2.INTER_LINEAR)
    d = os.path.join(OUT, "depth_e2e")
    os.makedirs(d, exist_ok=True)
    onnx.save(m, os.path.join(d, "model.onnx"))
    with open(os.path.join(d, "card.json"), "w") as f:
        json.dump(card, f, indent=1)
    np.save(os.path.join(d, "input_image.npy"), img)
    np.save(os.path.join(d, "expected.npy"), back.astype(np.float32))
    print("depth_e2e", img.shape, "->", back.shape)

    # inpaint_tiny
    nodes = [
        helper.make_node("Concat", ["image", "mask"], ["x"], axis=1),
        helper.make_node("Conv", ["x", "w1", "b1"], ["c1"], pads=[1, 1, 1, 1]),
        helper.make_node("BatchNormalization", ["c1", "g", "be", "mu", "var"], ["n1"], epsilon=1e-5),
        helper.make_node("Relu", ["n1"], ["r1"]),
        helper.make_node("Resize", ["r1", "", "half"], ["d1"], mode="nearest"),
        helper.make_node("Resize", ["d1", "", "double"], ["u1"], mode="nearest"),
        helper.make_node("Conv", ["u1", "w2", "b2"], ["c2"], pads=[1, 1, 1, 1]),
        helper.make_node("Sigmoid", ["c2"], ["s"]),
        helper.make_node("Mul", ["s", "k255"], ["output"]),
    ]
    inits = [init("w1", conv_w(8, 4, 3)), init("b1", rng.normal(0, 0.1, 8)),
             init("g", rng.uniform(0.5, 1.5, 8)), init("be", rng.normal(0, 0.2, 8)),
             init("mu", rng.normal(0, 0.3, 8)), init("var", rng.uniform(0.5, 2.0, 8)),
             init("half", [1, 1, 0.5, 0.5]), init("double", [1, 1, 2, 2]),
             init("w2", conv_w(3, 8, 3)), init("b2", rng.normal(0, 0.1, 3)), init("k255", [255.0])]
    g = helper.make_graph(nodes, "inpaint_tiny",
                          [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, 16, 16]),
                           helper.make_tensor_value_info("mask", TensorProto.FLOAT, [1, 1, 16, 16])],
                          [helper.make_tensor_value_info("output", TensorProto.FLOAT, [1, 3, 16, 16])], inits)
    m = helper.make_model(g, opset_imports=[helper.make_opsetid("", OPSET)])
    card = dict(model="model.onnx", inputs=dict(image="image", mask="mask"), output="output",
                layout="nchw", size=dict(policy="fixed", width=16, height=16), resize="bilinear",
                input_range=[0.0, 1.0], mean=[], std=[], output_kind="image",
                output_range=[0.0, 255.0], mask_value=1.0)
    mask = (rng.uniform(0, 1, (1, 1, 16, 16)) < 0.3).astype(np.float32)
    save("inpaint_tiny", m, card, dict(image=rng.uniform(0, 1, (1, 3, 16, 16)).astype(np.float32), mask=mask))

    # fixer_nhwc
    nodes = [
        helper.make_node("Transpose", ["image"], ["t"], perm=[0, 3, 1, 2]),
        helper.make_node("Conv", ["t", "w", "b"], ["c"], pads=[1, 1, 1, 1]),
        helper.make_node("Mul", ["c", "k"], ["cs"]),
        helper.make_node("Add", ["t", "cs"], ["a"]),
        helper.make_node("Clip", ["a", "lo", "hi"], ["cl"]),
        helper.make_node("Transpose", ["cl"], ["out"], perm=[0, 2, 3, 1]),
    ]
    inits = [init("w", conv_w(3, 3, 3)), init("b", rng.normal(0, 0.05, 3)), init("k", [0.1]),
             init("lo", 0.0), init("hi", 1.0)]
    g = helper.make_graph(nodes, "fixer_nhwc",
                          [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 10, 14, 3])],
                          [helper.make_tensor_value_info("out", TensorProto.FLOAT, [1, 10, 14, 3])], inits)
    m = helper.make_model(g, opset_imports=[helper.make_opsetid("", OPSET)])
    card = dict(model="model.onnx", inputs=dict(image="image"), output="out", layout="nhwc",
                size=dict(policy="native"), resize="bilinear", input_range=[0.0, 1.0], mean=[],
                std=[], output_kind="image")
    save("fixer_nhwc", m, card, dict(image=rng.uniform(0, 1, (1, 10, 14, 3)).astype(np.float32)))

    # resize_half: the half-pixel linear upsampling alone
    nodes = [helper.make_node("Resize", ["image", "", "s"], ["out"], mode="linear",
                              coordinate_transformation_mode="half_pixel")]
    g = helper.make_graph(nodes, "resize_half",
                          [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 2, 6, 8])],
                          [helper.make_tensor_value_info("out", TensorProto.FLOAT, [1, 2, 12, 16])],
                          [init("s", [1, 1, 2, 2])])
    m = helper.make_model(g, opset_imports=[helper.make_opsetid("", OPSET)])
    card = dict(model="model.onnx", inputs=dict(image="image"), output="out", layout="nchw",
                size=dict(policy="native"), resize="bilinear", input_range=[0.0, 1.0], mean=[],
                std=[], output_kind="image")
    save("resize_half", m, card, dict(image=rng.normal(0, 1, (1, 2, 6, 8)).astype(np.float32)))

    # bad_rank: image input of rank 3
    nodes = [helper.make_node("Relu", ["image"], ["depth"])]
    g = helper.make_graph(nodes, "bad_rank",
                          [helper.make_tensor_value_info("image", TensorProto.FLOAT, [3, 8, 8])],
                          [helper.make_tensor_value_info("depth", TensorProto.FLOAT, [3, 8, 8])])
    m = helper.make_model(g, opset_imports=[helper.make_opsetid("", OPSET)])
    d = os.path.join(OUT, "bad_rank")
    os.makedirs(d, exist_ok=True)
    onnx.save(m, os.path.join(d, "model.onnx"))
    card = dict(model="model.onnx", inputs=dict(image="image"), output="depth", layout="nchw",
                size=dict(policy="native"), resize="bilinear", input_range=[0.0, 1.0], mean=[],
                std=[], output_kind="depth")
    with open(os.path.join(d, "card.json"), "w") as f:
        json.dump(card, f, indent=1)
    with open(os.path.join(OUT, "meta.json"), "w") as f:
        json.dump(dict(tool=f"onnx {onnx.__version__} ReferenceEvaluator, opencv {cv2.__version__} (depth_e2e resize)",
                       generator="reference_data/generate/make_onnx_goldens.py", opset=OPSET), f, indent=1)


if __name__ == "__main__":
    main()
