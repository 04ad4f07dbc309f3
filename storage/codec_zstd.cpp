// The one place zstd is used.
#include <algorithm>
#include <limits>
#include <string>

#include <zstd.h>

#include "base/error.h"
#include "storage/codec.h"

namespace smr::storage {

namespace {
// One compression context and one decompression stream per thread, reused: creating them per
// call costs a multi-megabyte allocation (mmap/munmap and page faults) for every page.
struct Contexts {
  ZSTD_CCtx* c = ZSTD_createCCtx();
  ZSTD_DStream* d = ZSTD_createDStream();
  ~Contexts() {
    ZSTD_freeCCtx(c);
    ZSTD_freeDStream(d);
  }
};
Contexts& contexts() {
  thread_local Contexts ctx;
  if (ctx.c == nullptr || ctx.d == nullptr) throw_internal("zstd: out of memory");
  return ctx;
}
}  // namespace

Bytes zstd_compress(ByteView in, int level) {
  Bytes out(ZSTD_compressBound(in.size()));
  const std::size_t n =
      ZSTD_compressCCtx(contexts().c, out.data(), out.size(), in.data(), in.size(), level);
  if (ZSTD_isError(n)) {
    throw_internal(std::string("zstd_compress: ") + ZSTD_getErrorName(n));
  }
  out.resize(n);
  return out;
}

Bytes zstd_decompress(ByteView in, std::size_t max_bytes, std::string_view context) {
  const auto fail = [&](const std::string& what) {
    throw_corrupt(std::string(context) + ": zstd: " + what);
  };
  ZSTD_DStream* stream = contexts().d;
  ZSTD_DCtx_reset(stream, ZSTD_reset_session_only);
  // Grow the output as data actually arrives: a forged content size cannot force a huge buffer.
  const unsigned long long declared = ZSTD_getFrameContentSize(in.data(), in.size());
  if (declared == ZSTD_CONTENTSIZE_ERROR) fail("not a zstd frame");
  if (declared != ZSTD_CONTENTSIZE_UNKNOWN && declared > max_bytes) {
    fail("frame declares " + std::to_string(declared) + " bytes, more than the " +
         std::to_string(max_bytes) + " allowed");
  }
  // One byte more than allowed, so that an oversized output is detected rather than cut off.
  const std::size_t cap =
      max_bytes == std::numeric_limits<std::size_t>::max() ? max_bytes : max_bytes + 1;
  Bytes out;
  // A frame that declares a size within 256x the input and is all of the input decodes in one
  // call straight into its output (the stream below copies through its window: 1.4x the time).
  if (declared != ZSTD_CONTENTSIZE_UNKNOWN && declared <= 256 * in.size() + 65536 &&
      ZSTD_findFrameCompressedSize(in.data(), in.size()) == in.size()) {
    out.resize(std::size_t(declared));
    const std::size_t n = ZSTD_decompressDCtx(stream, out.data(), out.size(), in.data(), in.size());
    if (ZSTD_isError(n)) fail(ZSTD_getErrorName(n));
    if (n != out.size()) fail("frame shorter than it declares");
    return out;
  }
  // A declared size within 256x the input (zstd's usual ratios are far below) is trusted for the
  // first allocation, so a page decodes without regrowing; beyond that the output grows as data
  // arrives, so forged frames can at most take 256x their own size.
  if (declared != ZSTD_CONTENTSIZE_UNKNOWN && declared <= 256 * in.size() + 65536)
    out.resize(std::min<std::size_t>(cap, std::size_t(declared) + 4096));
  ZSTD_inBuffer input{in.data(), in.size(), 0};
  std::size_t produced = 0;
  for (;;) {
    if (out.size() - produced < 4096 && out.size() < cap) {
      out.resize(std::min(cap, std::max<std::size_t>(out.size() * 2, 16384)));
    }
    ZSTD_outBuffer output{out.data(), out.size(), produced};
    const std::size_t rc = ZSTD_decompressStream(stream, &output, &input);
    if (ZSTD_isError(rc)) fail(ZSTD_getErrorName(rc));
    produced = output.pos;
    if (produced > max_bytes) fail("output exceeds " + std::to_string(max_bytes) + " bytes");
    if (rc == 0) break;  // frame complete
    if (input.pos == input.size && output.pos < output.size) fail("truncated frame");
  }
  if (input.pos != input.size) fail("trailing bytes after the frame");
  out.resize(produced);
  return out;
}

}  // namespace smr::storage
