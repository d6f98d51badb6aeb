"""The linear MPC on OSQP (solver.MPC): its settings (config), the QP's fixed structure (qp) and the
obstacle and wall half-spaces (rows)."""
