#include "localizer/wire/status_name.h"

#include <gtest/gtest.h>

#include <string>

namespace evloc::wire {
namespace {

TEST(StatusCodeName, NamesTheCodesOfTheApi) {
  EXPECT_EQ(std::string(StatusCodeName(grpc::StatusCode::OK)), "OK");
  EXPECT_EQ(std::string(StatusCodeName(grpc::StatusCode::INVALID_ARGUMENT)), "INVALID_ARGUMENT");
  EXPECT_EQ(std::string(StatusCodeName(grpc::StatusCode::RESOURCE_EXHAUSTED)),
            "RESOURCE_EXHAUSTED");
  EXPECT_EQ(std::string(StatusCodeName(grpc::StatusCode::FAILED_PRECONDITION)),
            "FAILED_PRECONDITION");
  EXPECT_EQ(std::string(StatusCodeName(grpc::StatusCode::UNAVAILABLE)), "UNAVAILABLE");
  EXPECT_EQ(std::string(StatusCodeName(grpc::StatusCode::DATA_LOSS)), "other");
}

}  // namespace
}  // namespace evloc::wire
