// A user program built against the installed SDK only.
#include <dm/core/result.hpp>
#include <dm/core/types.hpp>

#include <iostream>

int main() {
  dm::Result<dm::Vec3> r = dm::Vec3(1.0, 2.0, 2.0);
  if (!r || r->norm() != 3.0) return 1;
  dm::Result<int> e = dm::fail(dm::ErrorCode::NotFound, "no such file", "x.nii", "check the path");
  std::cout << "consumer ok; sample error: " << e.error() << '\n';
  return e ? 1 : 0;
}
