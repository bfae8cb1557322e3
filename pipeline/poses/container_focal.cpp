#include "pipeline/poses/container_focal.h"

extern "C" {
#include <libavformat/avformat.h>
#include <libavutil/dict.h>
}

#include <cctype>
#include <cstdlib>

namespace cvd {
namespace {

std::string lower(std::string s) {
  for (auto& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

void append(const AVDictionary* d, std::vector<std::pair<std::string, std::string>>& out) {
  const AVDictionaryEntry* e = nullptr;
  while ((e = av_dict_get(d, "", e, AV_DICT_IGNORE_SUFFIX)))
    out.emplace_back(e->key ? e->key : "", e->value ? e->value : "");
}

}  // namespace

std::optional<ContainerFocal> focal_35mm_from_metadata(
    const std::vector<std::pair<std::string, std::string>>& tags) {
  for (const auto& [key, value] : tags) {
    const std::string k = lower(key);
    if (k.find("focal") == std::string::npos || k.find("35mm") == std::string::npos) continue;
    const char* begin = value.c_str();
    char* end = nullptr;
    const double f = std::strtod(begin, &end);
    if (end == begin || !(f > 0) || f > 2000) continue;
    return ContainerFocal{f, key};
  }
  return std::nullopt;
}

std::vector<std::pair<std::string, std::string>> read_container_metadata(
    const std::filesystem::path& video) {
  std::vector<std::pair<std::string, std::string>> out;
  AVFormatContext* ctx = nullptr;
  if (avformat_open_input(&ctx, video.string().c_str(), nullptr, nullptr) < 0) return out;
  append(ctx->metadata, out);
  for (unsigned s = 0; s < ctx->nb_streams; ++s) append(ctx->streams[s]->metadata, out);
  avformat_close_input(&ctx);
  return out;
}

std::optional<ContainerFocal> read_container_focal_35mm(const std::filesystem::path& video) {
  return focal_35mm_from_metadata(read_container_metadata(video));
}

}  // namespace cvd
