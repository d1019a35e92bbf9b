within;
model FirstOrderUnstable
  "First-order plant dx/dt = a*x + b*u, y = x (G(s) = b/(s - a)); unstable for a > 0"
  // Same equations as model.c (the FMU is built from the C source; tests/test_modelica_models.py
  // checks that both agree). a = 1 is the paper's 1/(s - 1), a = 1.5 gives 1/(s - 1.5).
  parameter Real a(unit = "1/s") = 1.0 "Pole location (1/s); a > 0 is unstable";
  parameter Real b(unit = "1/s") = 1.0 "Input gain";
  parameter Real x0 = 0.0 "Initial state";
  input Real u(start = 0.0) "Control input";
  output Real y "Plant output y = x";
protected
  Real x(start = x0, fixed = true) "State";
equation
  der(x) = a*x + b*u;
  y = x;
end FirstOrderUnstable;
