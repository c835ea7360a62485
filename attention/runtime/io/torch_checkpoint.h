// PyTorch checkpoints written by torch.save (the zip format of torch >= 1.6: `.pth`, `.pt`, `.bin`),
// read without Python and without executing anything.
//
// A checkpoint is a zip archive whose records all sit in one top-level folder, the prefix
// ("archive" in recent torch, the file stem in older ones):
//   <prefix>/data.pkl        the pickled object (protocol 2), tensors as persistent ids
//   <prefix>/data/<key>      one record per storage: raw little-endian elements
//   <prefix>/byteorder       "little" (torch >= 2.1; anything else is refused)
//   <prefix>/version, .data/serialization_id, .format_version, .storage_alignment  (ignored)
// torch writes the records stored (uncompressed) and 64-byte aligned, so tensors are used in place
// from the memory-mapped file. Deflated records are inflated once into owned memory.
//
// The pickle runs on a restricted machine: the opcodes of protocols 2-5 that build plain data
// (dicts, lists, tuples, strings, numbers), and only these globals:
//   collections.OrderedDict; torch._utils._rebuild_tensor_v2 / _rebuild_tensor /
//   _rebuild_parameter / _rebuild_parameter_with_state; torch._tensor._rebuild_from_type_v2 with
//   torch.Tensor or torch.nn.parameter.Parameter; the storage classes torch.{Float, Half, BFloat16,
//   Double, Long, Int, Byte, Char, Bool}Storage and torch.UntypedStorage; the dtype objects
//   torch.float32, torch.float16, ... . Any other global (os.system, builtins.eval, ...) is an
//   error naming the file and the global; nothing is ever called.
//
// Tensors: dtype from the storage class, shape, stride and storage offset from the rebuild call.
// Contiguous row-major tensors of stored records point into the mapping; strided tensors and
// tensors of deflated records are gathered into owned, contiguous memory (memfd mappings, so
// madvise(MADV_DONTNEED) by a loader evicts rather than zeroes them). Everything is checked
// before use: zip offsets and sizes inside the file, storage records present and of the size their
// persistent id claims, offset + extent inside the storage, byte sizes without overflow and below
// resource_limits().max_tensor_bytes, bounded pickle stack, memo and nesting.
//
// Selection of the state dict (key = ""):
//   1. the root holds tensors directly (a plain state dict): the whole root;
//   2. else "params_ema" if present (BasicSR's EMA weights, preferred over "params");
//   3. else the one of "params", "state_dict", "model" that is present (two or more: an error asking
//      for a key);
//   4. else the whole root.
// With a key, the root must be a dict holding that key. Nested dicts flatten with "." joins
// ("body.0.weight"), lists and tuples with their index; non-tensor leaves (ints, strings, None,
// the OrderedDict `_metadata`) are skipped.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "attention/runtime/io/safetensors.h"
#include "attention/runtime/status.h"

namespace macro {

struct TorchCheckpoint {
  std::string path;
  std::string archive_prefix;  // "archive", or the file stem for older torch
  std::string selected_key;    // "params_ema", ..., or "" when the root dict was used
  std::vector<TensorEntry> tensors;   // flattened names, in pickle order
  std::shared_ptr<const void> owner;  // keeps the mapped file and the owned copies alive
};

// Memory-maps path and reads it. key: "" selects automatically (above).
Result<TorchCheckpoint> read_torch_checkpoint(const std::string& path,
                                              const std::string& key = "");

// The same over bytes already in memory; name is used in messages. Tensors may point into data,
// which must outlive the result (owner keeps only the copies alive).
Result<TorchCheckpoint> read_torch_checkpoint_from_memory(const uint8_t* data, size_t size,
                                                          const std::string& name,
                                                          const std::string& key = "");

// True if the file starts with a zip local header ("PK\3\4"); false if it cannot be read.
bool file_has_zip_magic(const std::string& path);

}  // namespace macro
