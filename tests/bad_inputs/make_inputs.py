#!/usr/bin/env python3
# Writes the bad-input corpus of tests/bad_inputs/ (a development tool: the files are committed,
# the tests never run this). Standard library only. good.{png,jpg,bmp,tga} were written once with
# stb_image_write (16 x 12 RGB) and are the seeds of the image cases.
#   python3 tests/bad_inputs/make_inputs.py    (from anywhere; writes beside this script)
# cases.json (hand-written) says which command reads each file and the error it must give.
import gzip
import json
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))


def put(name, data):
    path = os.path.join(HERE, name)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as f:
        f.write(data.encode() if isinstance(data, str) else data)


def read(name):
    with open(os.path.join(HERE, name), "rb") as f:
        return f.read()


# ---- .ply (Inria layout, no normals, SH degree 0) -----------------------------------------------
PROPS = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
         "rot_0", "rot_1", "rot_2", "rot_3"]


def ply_header(count, props=PROPS, fmt="binary_little_endian", extra=""):
    lines = ["ply", f"format {fmt} 1.0", f"element vertex {count}"]
    lines += [p if p.startswith("property") else f"property float {p}" for p in props]
    return "\n".join(lines) + "\n" + extra + "end_header\n"


def vertex(i, x=None, scale=-2.0):
    # four Gaussians on a small square 3 m in front of the cameras below
    px = (i % 2) * 0.2 - 0.1 if x is None else x
    py = (i // 2) * 0.2 - 0.1
    return [px, py, 0.0, 1.0, 0.5, -0.5, 2.0, scale, scale, scale, 1.0, 0.0, 0.0, 0.0]


def ply_body(rows):
    return b"".join(struct.pack("<14f", *r) for r in rows)


good_rows = [vertex(i) for i in range(4)]
put("good.ply", ply_header(4).encode() + ply_body(good_rows))
put("ply_truncated.ply", ply_header(4).encode() + ply_body(good_rows)[: 2 * 56 + 20])
put("ply_count_oversize.ply", ply_header(3_000_000_000).encode() + ply_body(good_rows))
put("ply_count_negative.ply", ply_header(-5).encode() + ply_body(good_rows))
props_list = ["property list uchar float x"] + PROPS[1:]
put("ply_list_property.ply", ply_header(4, props_list).encode() + ply_body(good_rows))
put("ply_missing_rotation.ply", ply_header(4, PROPS[:10]).encode() +
    b"".join(struct.pack("<10f", *r[:10]) for r in good_rows))
flipped = bytearray(ply_header(4).encode() + ply_body(good_rows))
pos = flipped.find(b"end_header")
flipped[pos + 4] ^= 0x04  # end_header -> end_lheader
put("ply_header_byteflip.ply", bytes(flipped))
put("ply_all_nan.ply", ply_header(4).encode() +
    ply_body([vertex(i, x=float("nan")) for i in range(4)]))
put("ply_ascii_garbage.ply", ply_header(2, fmt="ascii") +
    "0 0 0 1 1 1 2 -2 -2 -2 1 0 0 0\n0 0 zero 1 1 1 2 -2 -2 -2 1 0 0 0\n")
put("ply_bad_format.ply", ply_header(4, fmt="binary_middle_endian").encode() + ply_body(good_rows))

# compressed .ply: one chunk row can hold 256 Gaussians; the file claims 300.
chunk_props = ["min_x", "min_y", "min_z", "max_x", "max_y", "max_z", "min_scale_x", "min_scale_y",
               "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z"]
cply = ("ply\nformat binary_little_endian 1.0\nelement chunk 1\n" +
        "".join(f"property float {p}\n" for p in chunk_props) +
        "element vertex 300\nproperty uint packed_position\nproperty uint packed_rotation\n"
        "property uint packed_scale\nproperty uint packed_color\nend_header\n").encode()
cply += struct.pack("<12f", -1, -1, -1, 1, 1, 1, -3, -3, -3, -1, -1, -1)
cply += b"".join(struct.pack("<4I", 0x80100400, 0xC0000000, 0x80100400, 0x808080FF)
                 for _ in range(300))
put("cply_chunks_short.compressed.ply", cply)

# ---- .splat: 32 bytes per Gaussian (pos f32x3, scale f32x3, rgba u8x4, rot u8x4) --------------
def splat_row(x, s=0.05):
    return struct.pack("<6f4B4B", x, 0.0, 0.0, s, s, s, 200, 100, 50, 255, 255, 128, 128, 128)


put("splat_truncated.splat", splat_row(0.0) + splat_row(0.1)[:20])
put("splat_empty.splat", b"")
put("splat_inf_scale.splat", splat_row(0.0, float("inf")) * 2)

# ---- .spz: gzip of a 16-byte header (magic 'NGSP', version, numPoints, shDegree, fractionalBits,
# flags, reserved) then the packed arrays ---------------------------------------------------------
def spz_header(n, version=2, magic=0x5053474E, sh=0):
    return struct.pack("<IIIBBBB", magic, version, n, sh, 12, 0, 0)


def spz_body(n):
    return (b"\0" * (9 * n) + b"\x80" * n + b"\x80" * (3 * n) + b"\x80" * (3 * n) + b"\x80" * (3 * n))


put("spz_count_oversize.spz", gzip.compress(spz_header(0x7FFFFFFF) + spz_body(2), mtime=0))
put("spz_bad_magic.spz", gzip.compress(spz_header(2, magic=0x12345678) + spz_body(2), mtime=0))
put("spz_bad_version.spz", gzip.compress(spz_header(2, version=99) + spz_body(2), mtime=0))
put("spz_truncated.spz", gzip.compress(spz_header(2) + spz_body(2), mtime=0)[:30])
put("spz_not_gzip.spz", spz_header(2) + spz_body(2))
put("spz_short_data.spz", gzip.compress(spz_header(50) + spz_body(2), mtime=0))

# ---- our cameras.json ---------------------------------------------------------------------------
W2C = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]]


def cam(**kw):
    c = {"name": "cam0", "width": 64, "height": 48, "fx": 60.0, "fy": 60.0, "cx": 32.0,
         "cy": 24.0, "world_to_camera": W2C}
    c.update(kw)
    return c


put("good_cameras.json", json.dumps([cam()], indent=1))
put("cameras_truncated.json", json.dumps([cam()], indent=1)[:150])
put("cameras_width_string.json", json.dumps([cam(width="64")]))
put("cameras_fx_negative.json", json.dumps([cam(fx=-60.0)]))
put("cameras_w2c_3x3.json", json.dumps([cam(world_to_camera=[r[:3] for r in W2C[:3]])]))
put("cameras_fy_overflow.json", json.dumps([cam()]).replace('"fy": 60.0', '"fy": 1e999'))
put("cameras_huge_size.json", json.dumps([cam(width=2_000_000, height=2_000_000, cx=1e6, cy=1e6)]))
put("cameras_not_a_list.json", json.dumps({"name": "cam0"}))

# ---- DL3DV-Closeup split ------------------------------------------------------------------------
GL = [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, -3], [0, 0, 0, 1]]
INTR = {"w": 64, "h": 48, "fl_x": 60, "fl_y": 60, "cx": 32, "cy": 24, "camera_model": "PINHOLE"}
split = {"scene": "abc", "data_factor": 4, "intrinsics": INTR, "training_frames": ["t.png"],
         "closeup_eval_pairs": [], "closeup_poses": {"c.png": GL}}
s = dict(split)
del s["intrinsics"]
put("split_no_intrinsics.json", json.dumps(s))
s = dict(split, closeup_poses={"c.png": [r[:3] for r in GL[:3]]})
put("split_pose_3x3.json", json.dumps(s))
s = dict(split, intrinsics=dict(INTR, fl_x="sixty"))
put("split_focal_string.json", json.dumps(s))

# ---- nerfstudio transforms.json -----------------------------------------------------------------
tr = dict(INTR, frames=[{"file_path": "images/a.png", "transform_matrix": GL}])
put("transforms_no_matrix/transforms.json",
    json.dumps(dict(INTR, frames=[{"file_path": "images/a.png"}])))
t = dict(tr)
del t["fl_x"], t["fl_y"]
put("transforms_no_focal.json", json.dumps(t))
put("transforms_frames_not_list.json", json.dumps(dict(INTR, frames={"a": 1})))
put("transforms_nan_matrix.json",
    json.dumps(dict(INTR, frames=[{"file_path": "a.png", "transform_matrix":
                                   [[float("nan"), 0, 0, 0]] + GL[1:]}])))

# ---- COLMAP text and binary ---------------------------------------------------------------------
put("colmap_text_empty/cameras.txt", "# Camera list with one line of data per camera:\n")
put("colmap_text_empty/images.txt", "# Image list with two lines of data per image:\n")
put("colmap_text_bad_model/cameras.txt", "1 FANCY_LENS 64 48 60 60 32 24\n")
put("colmap_text_bad_model/images.txt", "1 1 0 0 0 0 0 3 1 cam0\n\n")
put("colmap_text_short_params/cameras.txt", "1 PINHOLE 64 48 60 60\n")
put("colmap_text_short_params/images.txt", "1 1 0 0 0 0 0 3 1 cam0\n\n")
put("colmap_text_unknown_camera/cameras.txt", "1 PINHOLE 64 48 60 60 32 24\n")
put("colmap_text_unknown_camera/images.txt", "1 1 0 0 0 0 0 3 9 cam0\n\n")
put("colmap_text_nan_pose/cameras.txt", "1 PINHOLE 64 48 60 60 32 24\n")
put("colmap_text_nan_pose/images.txt", "1 1 0 0 0 nan 0 3 1 cam0\n\n")
cbin = struct.pack("<QiiQQ4d", 1, 1, 1, 64, 48, 60, 60, 32, 24)
ibin = struct.pack("<QI7dI", 1, 1, 1, 0, 0, 0, 0, 0, 3, 1) + b"cam0\0" + struct.pack("<Q", 0)
put("colmap_bin_truncated/cameras.bin", cbin[:30])
put("colmap_bin_truncated/images.bin", ibin)
put("colmap_bin_count_oversize/cameras.bin", struct.pack("<Q", 1 << 40) + cbin[8:])
put("colmap_bin_count_oversize/images.bin", ibin)
put("colmap_bin_points_oversize/cameras.bin", cbin)
put("colmap_bin_points_oversize/images.bin", ibin[:-8] + struct.pack("<Q", 1 << 50))

# ---- safetensors (nn-run --inputs for TAESD: input.image [N,3,H,W] F32) ------------------------
def safetensors(tensors, header_override=None):
    """tensors: list of (name, dtype, shape, bytes)."""
    header, data = {}, b""
    for name, dtype, shape, raw in tensors:
        header[name] = {"dtype": dtype, "shape": shape,
                        "data_offsets": [len(data), len(data) + len(raw)]}
        data += raw
    h = header_override if header_override is not None else json.dumps(header)
    h = h.encode()
    h += b" " * (-len(h) % 8)
    return struct.pack("<Q", len(h)) + h + data


img = struct.pack("<192f", *[((i * 37) % 64) / 64.0 for i in range(192)])  # [1,3,8,8]
put("good_image.safetensors", safetensors([("input.image", "F32", [1, 3, 8, 8], img)]))
good_st = read("good_image.safetensors")
put("st_truncated.safetensors", good_st[: len(good_st) - 100])
put("st_header_length_oversize.safetensors", struct.pack("<Q", 1 << 40) + good_st[8:])
put("st_header_not_json.safetensors",
    safetensors([], header_override='{"input.image": {"dtype": "F32", "shape": [1,3,8,8]'))
put("st_unknown_dtype.safetensors", safetensors([("input.image", "F33", [1, 3, 8, 8], img)]))
put("st_shape_vs_offsets.safetensors",
    safetensors([], header_override=json.dumps(
        {"input.image": {"dtype": "F32", "shape": [1, 3, 8, 9], "data_offsets": [0, 768]}})) + img)
put("st_offsets_past_end.safetensors",
    safetensors([], header_override=json.dumps(
        {"input.image": {"dtype": "F32", "shape": [1, 3, 8, 8], "data_offsets": [0, 1 << 36]}})) +
    img)
put("st_shape_overflow.safetensors",
    safetensors([], header_override=json.dumps(
        {"input.image": {"dtype": "F32", "shape": [1 << 40, 1 << 40, 1 << 40],
                         "data_offsets": [0, 768]}})) + img)
put("st_shape_negative.safetensors",
    safetensors([], header_override=json.dumps(
        {"input.image": {"dtype": "F32", "shape": [1, 3, -8, -8], "data_offsets": [0, 768]}})) + img)
put("st_wrong_name.safetensors", safetensors([("image", "F32", [1, 3, 8, 8], img)]))
put("st_wrong_shape.safetensors", safetensors([("input.image", "F32", [1, 4, 8, 6], img)]))
put("st_wrong_dtype.safetensors",
    safetensors([("input.image", "I32", [1, 3, 8, 8], struct.pack("<192i", *range(192)))]))
nan_img = bytearray(img)
nan_img[40:44] = struct.pack("<f", float("nan"))
put("st_nan.safetensors", safetensors([("input.image", "F32", [1, 3, 8, 8], bytes(nan_img))]))
inf_img = bytearray(img)
inf_img[0:4] = struct.pack("<f", float("inf"))
put("st_inf.safetensors", safetensors([("input.image", "F32", [1, 3, 8, 8], bytes(inf_img))]))

# A TAESD folder whose weight files hold the wrong tensors.
put("taesd_wrong_tensors/taesd_encoder.safetensors",
    safetensors([("0.weight", "F32", [64, 3, 3, 2], b"\0" * (64 * 3 * 3 * 2 * 4))]))
put("taesd_wrong_tensors/taesd_decoder.safetensors",
    safetensors([("0.weight", "F32", [64, 3, 3, 2], b"\0" * (64 * 3 * 3 * 2 * 4))]))

# A sharded U-Net (config.json of the golden unet-tiny) whose index is bad in three ways.
unet_config = {"sample_size": 16, "in_channels": 4, "out_channels": 4,
               "down_block_types": ["CrossAttnDownBlock2D", "CrossAttnDownBlock2D",
                                    "CrossAttnDownBlock2D", "DownBlock2D"],
               "up_block_types": ["UpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D",
                                  "CrossAttnUpBlock2D"],
               "block_out_channels": [32, 64, 64, 64], "layers_per_block": 2,
               "attention_head_dim": [2, 4, 4, 4], "cross_attention_dim": 48,
               "use_linear_projection": True, "norm_num_groups": 8, "norm_eps": 1e-05,
               "flip_sin_to_cos": True, "freq_shift": 0, "act_fn": "silu",
               "_class_name": "UNet2DConditionModel"}
INDEX = "diffusion_pytorch_model.safetensors.index.json"
for case, index in [
        ("unet_index_missing_shard", {"metadata": {"total_size": 8},
                                      "weight_map": {"conv_in.weight": "shard-00001.safetensors"}}),
        ("unet_index_not_json", None),
        ("unet_index_map_wrong_type", {"metadata": {}, "weight_map": ["conv_in.weight"]}),
]:
    put(f"{case}/config.json", json.dumps(unet_config, indent=1))
    put(f"{case}/{INDEX}", '{"weight_map": {"conv_in.weight": ' if index is None else
        json.dumps(index))
z = struct.pack("<64f", *([0.1] * 64))
ctx = struct.pack("<48f", *([0.2] * 48))
put("good_unet_inputs.safetensors", safetensors([("input.z", "F32", [1, 4, 4, 4], z),
                                                 ("input.ctx", "F32", [1, 1, 48], ctx)]))

# ---- CLIP tokenizer (pipeline folder without input.ctx reads tokenizer/) ------------------------
put("good_pipeline_inputs.safetensors",
    safetensors([("input.images", "F32", [1, 3, 8, 8], struct.pack("<192f", *([0.0] * 192)))]))
put("tokenizer_vocab_not_object/tokenizer/vocab.json", '["a", "b"]')
put("tokenizer_vocab_not_object/tokenizer/merges.txt", "#version: 0.2\na b\n")
put("tokenizer_merge_unknown/tokenizer/vocab.json",
    json.dumps({"a": 0, "b": 1, "<|startoftext|>": 2, "<|endoftext|>": 3}))
put("tokenizer_merge_unknown/tokenizer/merges.txt", "#version: 0.2\na b c\n")
put("tokenizer_id_negative/tokenizer/vocab.json",
    json.dumps({"a": -4, "b": 1, "<|startoftext|>": 2, "<|endoftext|>": 3}))
put("tokenizer_id_negative/tokenizer/merges.txt", "#version: 0.2\n")

# ---- images (macro metrics --pred X --gt good.png) ----------------------------------------------
png = read("good.png")
put("png_truncated.png", png[: len(png) // 2])
flip = bytearray(png)
idat = flip.find(b"IDAT")
flip[idat + 12] ^= 0xFF  # inside the zlib stream
put("png_byteflip.png", bytes(flip))
huge = bytearray(png)
huge[16:24] = struct.pack(">II", 100000, 100000)  # IHDR width, height (CRC now wrong too)
put("png_huge_dims.png", bytes(huge))
jpg = read("good.jpg")
put("jpeg_truncated.jpg", jpg[:200])
flipj = bytearray(jpg)
sof = flipj.find(b"\xff\xc0")
flipj[sof + 5:sof + 9] = struct.pack(">HH", 60000, 60000)  # SOF0 height, width
put("jpeg_huge_dims.jpg", bytes(flipj))
bmp = bytearray(read("good.bmp"))
bmp[18:26] = struct.pack("<ii", 30000, 30000)  # BITMAPINFOHEADER width, height
put("bmp_huge_dims.bmp", bytes(bmp))
put("bmp_truncated.bmp", read("good.bmp")[:100])
tga = bytearray(18)
tga[2] = 2  # uncompressed true colour
tga[12:16] = struct.pack("<HH", 4000, 4000)
tga[16] = 24
put("tga_short.tga", bytes(tga) + b"\x80" * 300)
put("image_garbage.png", b"this is not an image at all\n" * 4)
os.makedirs(os.path.join(HERE, "image_is_folder.png"), exist_ok=True)
put("image_is_folder.png/README", "A folder named like an image: reading it must fail cleanly.\n")
