"""The graph smoothers' model: the problem set-up, the C++ factors (``cpp_factors``) and the
custom interval factors (``interval_factors``), robust losses, the initial guess and the
extension hook (``extend``)."""
