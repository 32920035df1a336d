// parseHostPort: the "address:port" forms and the errors that name the field.
#include <dm/core/endpoint.hpp>

#include <gtest/gtest.h>

namespace {

TEST(HostPort, ParsesIpv4NamesAndBracketedIpv6) {
  auto a = dm::parseHostPort("192.168.1.20:47000", "device");
  ASSERT_TRUE(a) << a.error();
  EXPECT_EQ(a->host, "192.168.1.20");
  EXPECT_EQ(a->port, 47000);
  auto b = dm::parseHostPort("[::1]:5", "device");
  ASSERT_TRUE(b) << b.error();
  EXPECT_EQ(b->host, "::1");
  EXPECT_EQ(b->port, 5);
  auto c = dm::parseHostPort("console.local:0", "listen", true);
  ASSERT_TRUE(c) << c.error();
  EXPECT_EQ(c->host, "console.local");
  EXPECT_EQ(c->port, 0);
}

TEST(HostPort, RefusesWhatIsNotAddressPortNamingTheField) {
  for (const char* bad : {"127.0.0.1", ":47000", "host:", "host:65536", "host:12x", "host:-1"}) {
    auto r = dm::parseHostPort(bad, "listen");
    ASSERT_FALSE(r) << bad;
    EXPECT_EQ(r.error().code, dm::ErrorCode::InvalidArgument);
    EXPECT_EQ(r.error().where, "listen");
    EXPECT_NE(r.error().what.find(std::string("'") + bad + "'"), std::string::npos) << r.error().what;
  }
  EXPECT_FALSE(dm::parseHostPort("host:0", "device"));  // port 0 only when allowed
}

}  // namespace
