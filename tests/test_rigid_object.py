import numpy as np
import pytest
from scipy.integrate import solve_ivp

from multiarm_pin.exceptions import InputError
from multiarm_pin.model.rigid_object import ObjectState, RigidObject
from multiarm_pin.spatial import quaternion_derivative, quaternion_to_rotation


def test_box_inertia_closed_form():
    obj = RigidObject.box([0.8, 0.4, 0.3], 4.0)
    a, b, c = 0.8, 0.4, 0.3
    assert np.allclose(
        np.diag(obj.inertia), 4.0 / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    )


def test_polyhedron_inertia_matches_box():
    from multiarm_pin.model.polyhedron import box

    verts = box([0.8, 0.4, 0.3]).vertices
    assert np.allclose(
        RigidObject.from_vertices(verts, 4.0).inertia, RigidObject.box([0.8, 0.4, 0.3], 4.0).inertia
    )


def test_newton_euler_matches_finite_difference_of_momentum():
    """Integrate a tumbling body under a known torque; d/dt of the angular momentum about the
    COM (world axes) must equal the applied torque, and the linear momentum m g."""
    obj = RigidObject.box([0.9, 0.5, 0.2], 3.0)
    gravity = np.array([0.0, 0.0, -9.81])
    torque = np.array([0.3, -0.2, 0.5])

    def rhs(t, y):
        st = ObjectState(y[:3], y[3:7] / np.linalg.norm(y[3:7]), y[7:])
        a = obj.acceleration(st, gravity, np.concatenate([np.zeros(3), torque]))
        return np.concatenate([y[7:10], quaternion_derivative(st.quaternion, y[10:]), a])

    y0 = np.concatenate([[0, 0, 1.0], [0.1, 0.2, 0.3, 0.927], [0.5, 0, 0], [3.0, -1.0, 5.0]])
    y0[3:7] /= np.linalg.norm(y0[3:7])
    h = 1e-4
    sol = solve_ivp(rhs, (0, 1.0 + h), y0, rtol=1e-12, atol=1e-12, dense_output=True)

    def momentum(t):
        y = sol.sol(t)
        return obj.momentum(ObjectState(y[:3], y[3:7] / np.linalg.norm(y[3:7]), y[7:]))

    for t in (0.3, 0.7, 1.0):
        dL = (momentum(t + h) - momentum(t - h)) / (2 * h)
        assert np.allclose(dL[3:], torque, atol=1e-5)
        assert np.allclose(dL[:3], obj.mass * gravity, atol=1e-5)


def test_torque_free_body_conserves_energy_and_momentum():
    obj = RigidObject.box([0.9, 0.5, 0.2], 3.0)

    def rhs(t, y):
        st = ObjectState(y[:3], y[3:7], y[7:])
        return np.concatenate(
            [y[7:10], quaternion_derivative(y[3:7], y[10:]), obj.acceleration(st, np.zeros(3))]
        )

    y0 = np.concatenate([[0, 0, 0], [0, 0, 0, 1.0], [0.1, 0, 0], [0.1, 4.0, 0.2]])
    sol = solve_ivp(rhs, (0, 6.0), y0, rtol=1e-11, atol=1e-12)
    y = sol.y[:, -1]
    st0 = ObjectState(y0[:3], y0[3:7], y0[7:])
    st1 = ObjectState(y[:3], y[3:7] / np.linalg.norm(y[3:7]), y[7:])
    assert obj.kinetic_energy(st1) == pytest.approx(obj.kinetic_energy(st0), rel=1e-7)
    assert np.allclose(obj.momentum(st1), obj.momentum(st0), atol=1e-7)
    # the intermediate-axis spin (about body y) is unstable: the body really tumbles, its
    # body-frame angular velocity about y changes sign
    w_body_y = [
        (quaternion_to_rotation(yk[3:7] / np.linalg.norm(yk[3:7])).T @ yk[10:])[1] for yk in sol.y.T
    ]
    assert min(w_body_y) < -1.0


def test_object_validation():
    with pytest.raises(InputError, match="positive"):
        RigidObject.box([0.8, 0.4, 0.3], -1.0)
    with pytest.raises(InputError, match="box size"):
        RigidObject.box([0.8, 0.4], 1.0)
    with pytest.raises(InputError, match="triangle inequality"):
        RigidObject.box([1, 1, 1], 1.0, inertia=np.diag([1.0, 1.0, 3.0]))
    with pytest.raises(InputError, match="positive definite"):
        RigidObject.box([1, 1, 1], 1.0, inertia=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(InputError, match="unit quaternion"):
        ObjectState.create([0, 0, 0], [0, 0, 0, 2.0])
    with pytest.raises(InputError, match=r"expected shape \(4,\)"):
        ObjectState.create([0, 0, 0], [0, 0, 1.0])
    with pytest.raises(InputError, match="centre of mass"):
        RigidObject.from_vertices(np.random.default_rng(0).random((10, 3)) + 1.0, 1.0)


def test_state_rotation_matches_quaternion():
    q = np.array([0.2, -0.1, 0.4, 0.8])
    q /= np.linalg.norm(q)
    st = ObjectState.create([0, 0, 0], q)
    assert np.allclose(st.rotation, quaternion_to_rotation(q))
    assert np.allclose(st.rotation @ st.rotation.T, np.eye(3))
