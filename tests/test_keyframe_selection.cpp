// Keyframes of the pose stage: the setting's parser, motion measured on shifted images, spacing by
// accumulated motion with the gap bound, the cases that fall back to every frame, and the matched
// pair list (every frame reaches a keyframe; cost bounded).
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <set>

#include "engine/error.h"
#include "engine/random.h"
#include "pipeline/poses/keyframe_selection.h"

namespace cvd {
namespace {

void expect_valid(const KeyframeSelection& s, int n, int max_gap) {
  ASSERT_FALSE(s.keyframes.empty());
  EXPECT_EQ(s.keyframes.front(), 0);
  EXPECT_EQ(s.keyframes.back(), n - 1);
  for (size_t k = 1; k < s.keyframes.size(); ++k) {
    EXPECT_GT(s.keyframes[k], s.keyframes[k - 1]);
    if (max_gap > 0) {
      EXPECT_LE(s.keyframes[k] - s.keyframes[k - 1], max_gap) << "at " << k;
    }
  }
}

TEST(KeyframeSelection, ParsesTheSetting) {
  EXPECT_EQ(parse_keyframe_mode("auto", "x").mode, KeyframeMode::automatic);
  EXPECT_EQ(parse_keyframe_mode("all", "x").mode, KeyframeMode::all);
  KeyframeOptions c = parse_keyframe_mode("25", "x");
  EXPECT_EQ(c.mode, KeyframeMode::count);
  EXPECT_EQ(c.count, 25);
  EXPECT_EQ(keyframe_mode_name(c), "25");
  for (const char* bad : {"", "1", "0", "-3", "12x", "some"}) {
    try {
      parse_keyframe_mode(bad, "--colmap-keyframes");
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("--colmap-keyframes"), std::string::npos) << e.what();
    }
  }
}

TEST(KeyframeSelection, EvenMotionGivesEvenKeyframes) {
  KeyframeOptions o;
  std::vector<double> motion(150, 0.01);  // 1% of the long side per frame
  motion[0] = 0;
  KeyframeSelection s = select_keyframes(motion, o);
  ASSERT_FALSE(s.all_frames) << s.reason;
  expect_valid(s, 150, o.max_gap);
  EXPECT_NEAR(s.total_motion, 1.49, 1e-9);
  // ceil(1.49 / 0.04) + 1 = 39 keyframes, about 4 frames apart.
  EXPECT_NEAR(double(s.keyframes.size()), 39.0, 1.0);
  for (size_t k = 1; k < s.keyframes.size(); ++k)
    EXPECT_NEAR(s.keyframes[k] - s.keyframes[k - 1], 149.0 / 38.0, 1.01);
}

TEST(KeyframeSelection, AStillCameraStillGetsKeyframesWithinTheGap) {
  KeyframeOptions o;
  KeyframeSelection s = select_keyframes(std::vector<double>(300, 0.0), o);
  ASSERT_FALSE(s.all_frames) << s.reason;
  expect_valid(s, 300, o.max_gap);
  EXPECT_GE(int(s.keyframes.size()), 299 / o.max_gap + 1);
  EXPECT_LE(int(s.keyframes.size()), 2 * (299 / o.max_gap + 1));
}

TEST(KeyframeSelection, AFastPanGetsMoreKeyframesThanASlowStretch) {
  KeyframeOptions o;
  std::vector<double> motion(200, 0.002);
  for (int k = 150; k < 200; ++k) motion[k] = 0.03;
  KeyframeSelection s = select_keyframes(motion, o);
  ASSERT_FALSE(s.all_frames) << s.reason;
  expect_valid(s, 200, o.max_gap);
  int slow = 0, fast = 0;
  for (int k : s.keyframes) (k < 150 ? slow : fast) += 1;
  EXPECT_GT(fast, 2 * slow / 3) << "50 fast frames vs 150 slow ones";
  EXPECT_GE(fast, 30);  // 1.5 of motion at 4% per keyframe: ~37
}

TEST(KeyframeSelection, ShortOrFastClipsUseEveryFrame) {
  KeyframeOptions o;
  EXPECT_TRUE(select_keyframes(std::vector<double>(10, 0.01), o).all_frames);
  // Fast motion everywhere: keyframes would be most of the frames.
  EXPECT_TRUE(select_keyframes(std::vector<double>(100, 0.05), o).all_frames);
  KeyframeOptions all = parse_keyframe_mode("all", "x");
  KeyframeSelection s = select_keyframes(std::vector<double>(500, 0.01), all);
  EXPECT_TRUE(s.all_frames);
  EXPECT_EQ(s.keyframes.size(), 500u);
}

TEST(KeyframeSelection, CountModeGivesThatManyKeyframes) {
  KeyframeOptions o = parse_keyframe_mode("20", "x");
  std::vector<double> motion(150, 0.01);
  KeyframeSelection s = select_keyframes(motion, o);
  ASSERT_FALSE(s.all_frames);
  expect_valid(s, 150, 0);
  EXPECT_EQ(s.keyframes.size(), 20u);
}

TEST(KeyframeSelection, MatchPairsReachAKeyframeFromEveryFrameAndStayLinear) {
  KeyframeOptions o;
  const int n = 600;
  KeyframeSelection s = select_keyframes(std::vector<double>(n, 0.01), o);
  ASSERT_FALSE(s.all_frames);
  const int K = int(s.keyframes.size());
  auto pairs = keyframe_match_pairs(n, s.keyframes, 5, o);
  std::set<std::pair<int, int>> set(pairs.begin(), pairs.end());
  EXPECT_EQ(set.size(), pairs.size()) << "no duplicates";
  std::set<int> keys(s.keyframes.begin(), s.keyframes.end());
  std::vector<int> key_partners(n, 0);
  for (auto [a, b] : pairs) {
    EXPECT_LT(a, b);
    EXPECT_GE(a, 0);
    EXPECT_LT(b, n);
    if (keys.count(b)) ++key_partners[a];
    if (keys.count(a)) ++key_partners[b];
  }
  for (int i = 0; i < n; ++i) EXPECT_GE(key_partners[i], 1) << "frame " << i;
  for (int a = 0; a + 1 < K; ++a)
    EXPECT_TRUE(set.count({s.keyframes[a], s.keyframes[a + 1]})) << "keyframes " << a;
  // A loop candidate far along the keyframes.
  EXPECT_TRUE(set.count({s.keyframes[0], s.keyframes[2 * o.keyframe_overlap]}));
  const double bound = n * (5 + 2) + K * (o.keyframe_overlap + std::log2(K) + 1);
  EXPECT_LE(double(pairs.size()), bound);
}

TEST(KeyframeSelection, MotionIsTheMedianShiftAsAFractionOfTheLongSide) {
  Generator gen(5);
  cv::Mat noise(240, 360, CV_8UC3);
  for (int y = 0; y < noise.rows; ++y)
    for (int x = 0; x < noise.cols; ++x)
      noise.at<cv::Vec3b>(y, x) = cv::Vec3b(uchar(gen.randint(0, 256)), uchar(gen.randint(0, 256)),
                                            uchar(gen.randint(0, 256)));
  cv::Mat textured;
  cv::GaussianBlur(noise, textured, cv::Size(0, 0), 2.0);
  std::vector<cv::Mat> frames;
  for (int k = 0; k < 3; ++k) {  // 0, 9 and 18 px to the right in a 320 x 240 window
    frames.push_back(textured(cv::Rect(20 - 9 * (k - 1) + 9, 0, 320, 240)).clone());
  }
  std::vector<double> m = consecutive_motion(frames, 160);
  ASSERT_EQ(m.size(), 3u);
  EXPECT_EQ(m[0], 0.0);
  EXPECT_NEAR(m[1], 9.0 / 320.0, 0.15 * 9.0 / 320.0);
  EXPECT_NEAR(m[2], 9.0 / 320.0, 0.15 * 9.0 / 320.0);
}

}  // namespace
}  // namespace cvd
