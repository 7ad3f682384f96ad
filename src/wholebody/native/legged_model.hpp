// A Pinocchio model restricted to the joints of legged robots (free flyer, revolute and
// prismatic about the joint axes), so that every algorithm is instantiated for 10 joint types
// instead of Pinocchio's 25, which makes the native cycle much quicker to compile.
// Pinocchio 4 needs the mimic joint in any collection; it is declared but never built here.
#pragma once

#include <pinocchio/multibody.hpp>

namespace wholebody
{
  template<typename _Scalar, int _Options>
  struct JointCollectionLegged
  {
    typedef _Scalar Scalar;
    static constexpr int Options = _Options;

    typedef pinocchio::JointModelRevoluteTpl<Scalar, Options, 0> JointModelRX;
    typedef pinocchio::JointModelRevoluteTpl<Scalar, Options, 1> JointModelRY;
    typedef pinocchio::JointModelRevoluteTpl<Scalar, Options, 2> JointModelRZ;
    typedef pinocchio::JointModelPrismaticTpl<Scalar, Options, 0> JointModelPX;
    typedef pinocchio::JointModelPrismaticTpl<Scalar, Options, 1> JointModelPY;
    typedef pinocchio::JointModelPrismaticTpl<Scalar, Options, 2> JointModelPZ;
    typedef pinocchio::JointModelRevoluteUnalignedTpl<Scalar, Options> JointModelRevoluteUnaligned;
    typedef pinocchio::JointModelPrismaticUnalignedTpl<Scalar, Options> JointModelPrismaticUnaligned;
    typedef pinocchio::JointModelFreeFlyerTpl<Scalar, Options> JointModelFreeFlyer;
    // continuous joints (unbounded revolute: q = (cos, sin), one velocity)
    typedef pinocchio::JointModelRevoluteUnboundedTpl<Scalar, Options, 0> JointModelRUBX;
    typedef pinocchio::JointModelRevoluteUnboundedTpl<Scalar, Options, 1> JointModelRUBY;
    typedef pinocchio::JointModelRevoluteUnboundedTpl<Scalar, Options, 2> JointModelRUBZ;
    typedef pinocchio::JointModelRevoluteUnboundedUnalignedTpl<Scalar, Options>
      JointModelRevoluteUnboundedUnaligned;
    typedef pinocchio::JointModelMimicTpl<Scalar, Options, JointCollectionLegged> JointModelMimic;
    typedef pinocchio::JointModelCompositeTpl<Scalar, Options, JointCollectionLegged>
      JointModelComposite;
    typedef boost::variant<
      JointModelRX, JointModelRY, JointModelRZ, JointModelFreeFlyer, JointModelRevoluteUnaligned,
      JointModelPX, JointModelPY, JointModelPZ, JointModelPrismaticUnaligned, JointModelRUBX,
      JointModelRUBY, JointModelRUBZ, JointModelRevoluteUnboundedUnaligned,
      boost::recursive_wrapper<JointModelMimic>>
      JointModelVariant;

    typedef pinocchio::JointDataRevoluteTpl<Scalar, Options, 0> JointDataRX;
    typedef pinocchio::JointDataRevoluteTpl<Scalar, Options, 1> JointDataRY;
    typedef pinocchio::JointDataRevoluteTpl<Scalar, Options, 2> JointDataRZ;
    typedef pinocchio::JointDataPrismaticTpl<Scalar, Options, 0> JointDataPX;
    typedef pinocchio::JointDataPrismaticTpl<Scalar, Options, 1> JointDataPY;
    typedef pinocchio::JointDataPrismaticTpl<Scalar, Options, 2> JointDataPZ;
    typedef pinocchio::JointDataRevoluteUnalignedTpl<Scalar, Options> JointDataRevoluteUnaligned;
    typedef pinocchio::JointDataPrismaticUnalignedTpl<Scalar, Options> JointDataPrismaticUnaligned;
    typedef pinocchio::JointDataFreeFlyerTpl<Scalar, Options> JointDataFreeFlyer;
    typedef pinocchio::JointDataRevoluteUnboundedTpl<Scalar, Options, 0> JointDataRUBX;
    typedef pinocchio::JointDataRevoluteUnboundedTpl<Scalar, Options, 1> JointDataRUBY;
    typedef pinocchio::JointDataRevoluteUnboundedTpl<Scalar, Options, 2> JointDataRUBZ;
    typedef pinocchio::JointDataRevoluteUnboundedUnalignedTpl<Scalar, Options>
      JointDataRevoluteUnboundedUnaligned;
    typedef pinocchio::JointDataMimicTpl<Scalar, Options, JointCollectionLegged> JointDataMimic;
    typedef pinocchio::JointDataCompositeTpl<Scalar, Options, JointCollectionLegged>
      JointDataComposite;
    typedef boost::variant<
      JointDataRX, JointDataRY, JointDataRZ, JointDataFreeFlyer, JointDataRevoluteUnaligned,
      JointDataPX, JointDataPY, JointDataPZ, JointDataPrismaticUnaligned, JointDataRUBX,
      JointDataRUBY, JointDataRUBZ, JointDataRevoluteUnboundedUnaligned,
      boost::recursive_wrapper<JointDataMimic>>
      JointDataVariant;
  };

  typedef pinocchio::ModelTpl<double, 0, JointCollectionLegged> LeggedModel;
  typedef pinocchio::DataTpl<double, 0, JointCollectionLegged> LeggedData;
} // namespace wholebody
