// The example programs (examples/) build and do what they say: train_and_render trains a network on a
// generated volume, prints its PSNR, saves it, and writes a PNG of the rendered network.
#include <gtest/gtest.h>
#include <cstdio>
#include <string>
#include "vnr/vnr.h"
#include "vnr/render/image.h"
#include "test_support.h"

using namespace vnr;
using namespace vnr::test;

TEST(Examples, TrainAndRenderTrainsEvaluatesRendersAndSaves) {
  const std::string d = temp_dir("vnr_example");
  const std::string exe = std::string(VNR_EXAMPLES_DIR) + "/example_train_and_render";
  const std::string out = d + "/stdout.txt";
  const int st = std::system((exe + " '' " + d + " 300 >" + out + " 2>&1").c_str());
  const std::string text = read_file(out);
  ASSERT_EQ(st, 0) << text;
  double psnr = 0, ssim = 0, ratio = 0;
  const size_t at = text.find("PSNR ");
  ASSERT_NE(at, std::string::npos) << text;
  ASSERT_EQ(std::sscanf(text.c_str() + at, "PSNR %lf dB, SSIM %lf, compression ratio %lf", &psnr, &ssim, &ratio), 3);
  EXPECT_GT(psnr, 25.0) << "300 steps of the small config on a 64^3 Marschner-Lobb volume";
  EXPECT_GT(ssim, 0.5);

  // The saved model is the one that was measured: same size, so the same compression ratio.
  const Model model = load_model(d + "/example.vnr");
  EXPECT_NEAR(compression_ratio(model), ratio, 0.05);
  EXPECT_EQ(model.dims, (Int3{64, 64, 64}));
  const Image img = read_image(d + "/example.png");
  EXPECT_EQ(img.width, 256);
  EXPECT_EQ(img.height, 256);
  double lit = 0;
  for (const Vec4f& p : img.pixels) lit += p.w > 0.05f;
  EXPECT_GT(lit / double(img.pixels.size()), 0.2) << "the volume covers a good part of the image";
}
