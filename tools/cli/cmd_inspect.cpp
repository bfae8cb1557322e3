// `cvd inspect FILE.cvdw [--tensors]`: what a weights file holds, and whether it is intact.
#include <fmt/format.h>

#include <cstdio>
#include <string>

#include "engine/cvdw.h"
#include "engine/error.h"
#include "tools/cli/command.h"

namespace cvd::cli {

namespace {

struct InspectOptions {
  std::string file;
  bool tensors = false;
};

std::string with_thousands(int64_t n) {
  const std::string digits = std::to_string(n < 0 ? -n : n);
  std::string out = n < 0 ? "-" : "";
  for (size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) out.push_back(',');
    out.push_back(digits[i]);
  }
  return out;
}

void run_inspect(const InspectOptions& o) {
  CvdwReader reader(o.file);
  const CvdwHeader& h = reader.header();
  int64_t total = 0, params = 0, buffers = 0;
  std::vector<std::string> corrupt;
  std::vector<bool> ok(h.tensors.size());
  for (size_t i = 0; i < h.tensors.size(); ++i) {
    const CvdwEntry& e = h.tensors[i];
    const int64_t n = shape_numel(e.shape);
    total += n;
    if (e.kind == "parameter") params += n;
    if (e.kind == "buffer") buffers += n;
    ok[i] = reader.computed_crc32(i) == e.crc32;
    if (!ok[i]) corrupt.push_back(e.name);
  }
  std::printf("file:        %s (%s bytes, cvdw version %u)\n", o.file.c_str(),
              with_thousands(static_cast<int64_t>(h.file_size)).c_str(), h.version);
  std::printf("model:       %s\n", h.model.empty() ? "(none)" : h.model.c_str());
  std::printf("config:      %s\n", h.config.dump().c_str());
  std::printf("tensors:     %zu\n", h.tensors.size());
  std::printf("elements:    %s\n", with_thousands(total).c_str());
  if (params || buffers) {
    std::printf("parameters:  %s\n", with_thousands(params).c_str());
    std::printf("buffers:     %s\n", with_thousands(buffers).c_str());
  }
  std::printf(
      "CRC:         %s\n",
      corrupt.empty()
          ? "all ok"
          : fmt::format("{} of {} tensors corrupt", corrupt.size(), h.tensors.size()).c_str());
  if (o.tensors) {
    size_t width = 4;
    for (const auto& e : h.tensors) width = std::max(width, e.name.size());
    std::printf("\n%-*s  %-5s  %-22s  %-10s  %s\n", static_cast<int>(width), "name", "dtype",
                "shape", "kind", "crc32");
    for (size_t i = 0; i < h.tensors.size(); ++i) {
      const CvdwEntry& e = h.tensors[i];
      std::printf("%-*s  %-5s  %-22s  %-10s  %08x %s\n", static_cast<int>(width), e.name.c_str(),
                  dtype_name(e.dtype), shape_str(e.shape).c_str(),
                  e.kind.empty() ? "-" : e.kind.c_str(), e.crc32, ok[i] ? "ok" : "MISMATCH");
    }
  }
  std::fflush(stdout);
  if (!corrupt.empty()) {
    std::string names;
    for (size_t i = 0; i < corrupt.size() && i < 10; ++i)
      names += (i ? ", '" : "'") + corrupt[i] + "'";
    if (corrupt.size() > 10) names += fmt::format(", ... and {} more", corrupt.size() - 10);
    fail(ErrorCategory::format, "{}: CRC mismatch in tensor {} (file truncated or corrupt)", o.file,
         names);
  }
}

const CommandRegistration inspect_registration(90, [](CLI::App& app) {
  auto opts = std::make_shared<InspectOptions>();
  CLI::App* sub = app.add_subcommand(
      "inspect",
      "Show the model name, config and tensors of a .cvdw weights file and check its CRCs");
  sub->add_option("file", opts->file, "The .cvdw file")->required();
  sub->add_flag("--tensors", opts->tensors, "List every tensor: name, dtype, shape, kind, CRC");
  sub->callback([opts]() { run_inspect(*opts); });
});

}  // namespace

}  // namespace cvd::cli
